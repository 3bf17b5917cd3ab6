; unexpected ']' @ 2:15
G1 F100 X[1 + ]
