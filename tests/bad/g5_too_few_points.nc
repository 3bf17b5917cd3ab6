; at least the order @ 5:1
F100
G5.2 X0 Y1 P1 L4
X1 Y1 P1
G5.3
