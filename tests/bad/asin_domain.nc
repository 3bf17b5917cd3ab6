; ASIN argument 1.5 outside [-1, 1] @ 2:9
G1 F100 X[ASIN[1.5]]
