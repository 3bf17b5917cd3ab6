; Z word with G5 (splines are planar) @ 2:15
G5 F100 X1 Y1 Z1 I1 J0 P1 Q0
