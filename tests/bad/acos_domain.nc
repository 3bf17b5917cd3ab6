; ACOS argument -2 outside [-1, 1] @ 2:9
G1 F100 X[ACOS[-2]]
