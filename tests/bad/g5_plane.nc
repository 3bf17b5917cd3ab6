; G5 splines are only allowed in the XY plane @ 2:5
G18 G5 F100 X1 Z1 I1 J0 P1 Q0
