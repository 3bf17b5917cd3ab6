; X word repeated @ 2:10
G1 X1 Y2 X3 F100
