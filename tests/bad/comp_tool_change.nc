; Cannot change tools with cutter radius compensation on @ 4:4
G21 F100
G41.1 D2 G1 X10 Y0
T1 M6
