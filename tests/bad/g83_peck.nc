; G83 (canned cycle) is not supported @ 2:1
G83 X1 Y1 Z-1 R1 Q0.5 F100
