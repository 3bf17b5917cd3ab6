; the first knot is repeated 5 times @ 3:1
F600
G6.2 P3 K0 X0 Y0 R1
K0 X1 Y1 R1
K0 X2 Y-1 R1
K0 X3 Y1 R1
K0 X4 Y0 R1
K1
K1
K1
M2
