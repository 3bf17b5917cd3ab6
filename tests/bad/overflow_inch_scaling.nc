; X1e+307 is out of range @ 2:13
G20 G1 F100 X[10**307]
