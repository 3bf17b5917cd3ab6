; G0 and G1 are in the same modal group @ 2:4
G0 G1 X1 F100
