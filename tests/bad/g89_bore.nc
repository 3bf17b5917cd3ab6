; Dwell time p word missing with g89 @ 2:1
G89 X1 Y1 Z-1 R1 F100
