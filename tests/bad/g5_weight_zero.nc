; NURBS weight P0 must be > 0 @ 4:7
F100
G5.2 X0 Y1 P1 L3
X1 Y1 P0
