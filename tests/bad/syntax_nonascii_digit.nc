; G-code is ASCII @ 2:10
G1 F100 X١٢
