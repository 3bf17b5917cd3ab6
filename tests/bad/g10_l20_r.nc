; R not allowed in G10 L20 @ 2:15
G10 L20 P1 X0 R30
