; K word with no arc (G2/G3), G6.2 NURBS or G87 @ 3:21
G0 Z5
G83 X1 Y1 Z-1 R2 Q1 K2 F100
M2
