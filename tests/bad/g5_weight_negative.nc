; NURBS weight P-2 must be > 0 @ 3:12
F100
G5.2 X0 Y1 P-2 L3
