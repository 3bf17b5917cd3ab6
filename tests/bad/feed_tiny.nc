; is out of range (1e-09 to 1e+09 mm/min, or 0) @ 2:1
F0.0000000000001 G1 X1
