; K word given for an arc in the XY plane @ 2:18
G17 G2 X10 Y0 I5 K1 F100
