; G81 (canned cycle) is not supported @ 2:1
G81 X1 Y1 Z-1 R1 F100
