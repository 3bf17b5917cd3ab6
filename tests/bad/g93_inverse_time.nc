; inverse time feed (G93) is not supported @ 2:1
G93 G1 X1 F2
