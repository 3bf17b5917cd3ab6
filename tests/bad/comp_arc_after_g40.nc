; The move just after exiting cutter compensation mode must be straight, not an arc @ 6:1
G21 F100
G41.1 D2 G1 X10 Y0
G1 X20 Y0
G40
G2 X30 Y0 R5
