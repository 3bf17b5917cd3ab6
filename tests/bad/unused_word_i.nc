; I word with no arc @ 2:7
G1 X1 I2 F100
