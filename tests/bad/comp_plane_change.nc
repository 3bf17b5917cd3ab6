; Cannot change planes with cutter radius compensation on @ 4:1
G21 F100
G41.1 D2 G1 X10 Y0
G18
