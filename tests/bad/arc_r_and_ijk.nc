; both R and I/J/K @ 2:14
G2 X10 Y0 I5 R5 F100
