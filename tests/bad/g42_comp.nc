; Tool radius not less than arc radius with comp @ 4:1
G21 F100
G42.1 D10 G1 X20 Y0
G2 X30 Y0 R5
