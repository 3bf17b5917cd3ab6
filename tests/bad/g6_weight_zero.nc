; NURBS weight R0 must be > 0 @ 4:10
F100
G6.2 P3 K0 X0 Y0 R1
K0 X1 Y1 R0
