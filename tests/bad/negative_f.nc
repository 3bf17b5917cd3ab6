; negative feed F-100 @ 2:7
G1 X1 F-100
