; order L3.5 must be an integer up to 8 @ 3:15
F100
G5.2 X0 Y1 P1 L3.5
