; more than 100 nested calls @ 3:1
o<r> sub
o<r> call
o<r> endsub
o<r> call
