; Cannot put an a in canned cycle @ 3:18
G21 G0 Z5 F100
G81 X1 Y1 Z-1 R1 A0
