; M99 in the main program @ 3:1
G0 X1
M99
M2
