; o100 return/endsub outside a subroutine @ 3:1
G0 X1
o100 endsub
