; G95 (feed per revolution) is not supported @ 2:1
G95 G1 X1 F0.1
