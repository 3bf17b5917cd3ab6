; NURBS with zero feed @ 2:6
G6.2 P3 K0 X0 Y0 R1
