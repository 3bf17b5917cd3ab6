; unexpected character '_' @ 2:11
G1 F100 X1_0
