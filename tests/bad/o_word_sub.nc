; O-words @ 2:1
o100 sub
G1 X1
o100 endsub
