; G89 (canned cycle) is not supported @ 2:1
G89 X1 Y1 Z-1 R1 P1 F100
