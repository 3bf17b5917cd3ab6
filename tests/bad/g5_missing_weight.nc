; needs a positive weight P @ 4:1
F100
G5.2 X0 Y1 P1 L3
X1 Y1
