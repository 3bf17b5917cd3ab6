; Cannot use canned cycles with cutter compensation on @ 4:1
G21 G17 F100
G41.1 D2 G1 X10 Y0
G81 X20 Y0 Z-1 R1
