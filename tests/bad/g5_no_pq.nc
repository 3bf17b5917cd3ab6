; G5 needs both P and Q @ 2:1
G5 F100 X1 Y1 I1 J0 P0
