; o9 sub without endsub @ 3:1
G0 X1
o9 sub
G0 X2
