; G5.1 in inverse time feed mode (G93) is not supported @ 2:5
G93 G5.1 F100 X1 Y1 I1 J0
