; NURBS with zero feed @ 2:1
G5.2 X0 Y1 P1 L3
