; Z word in a G5.2 block in the XY plane @ 3:12
F100
G5.2 X0 Y1 Z1 P1 L3
