; not closed by G5.3 @ 5:1
F100
G5.2 X0 Y1 P1 L3
X1 Y1 P1
G1 X5
