; order L9 must be an integer up to 8 @ 3:15
F100
G5.2 X0 Y1 P1 L9
