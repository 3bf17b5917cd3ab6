; full circle in radius format @ 2:10
G2 X0 Y0 R5 F100
