; P word with no G4, G10, G64, arc @ 4:4
G0 Z5
G81 X1 Y1 Z-1 R2 F100
X2 P1
M2
