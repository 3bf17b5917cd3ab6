; must be the current position @ 3:6
F100
G6.2 P3 K0 X5 Y0 R1
