; P without X and Y @ 4:1
F100
G5.2 X0 Y1 P1 L3
P2
G5.3
