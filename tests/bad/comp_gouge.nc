; Straight feed in concave corner cannot be reached by the tool without gouging @ 6:1
G21 F100
G41.1 D4 G1 X10 Y0
G1 X20
G1 Y1
G1 X21
