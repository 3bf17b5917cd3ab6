; MOD by zero @ 2:9
G1 F100 X[5 MOD 0]
