; smaller than half the distance @ 2:11
G2 X10 Y0 R4 F100
