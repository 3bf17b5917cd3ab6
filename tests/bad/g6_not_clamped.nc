; must be clamped @ 3:1
F100
G6.2 P3 K0 X0 Y0 R1
K0 X1 Y1 R1
K1 X2 Y0 R1
K1
K2
K2
