; no subroutine O7 in the program @ 3:5
G0 X1
M98 P7 L2
M2
