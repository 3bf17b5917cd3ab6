; without its knot K @ 4:1
F100
G6.2 P3 K0 X0 Y0 R1
X1 Y1 R1
