; no closing G5.3 @ 3:1
F100
G5.2 X0 Y1 P1 L3
X1 Y1 P1
X2 Y0 P1
