; unknown word E @ 2:11
G1 F100 X1e3
