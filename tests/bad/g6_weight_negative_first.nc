; NURBS weight R-1 must be > 0 @ 3:18
F100
G6.2 P3 K0 X0 Y0 R-1
