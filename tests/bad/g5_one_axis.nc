; G5.2 control points need both X and Y @ 3:6
F100
G5.2 X1 P1 L3
