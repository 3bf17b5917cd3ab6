; I word given for an arc in the YZ plane @ 2:15
G19 G2 Y10 Z0 I1 J5 F100
