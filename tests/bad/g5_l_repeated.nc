; L word inside a G5.2 block @ 4:10
F100
G5.2 X0 Y1 P1 L3
X1 Y1 P1 L3
