; SQRT of a negative number @ 2:9
G1 F100 X[SQRT[-4]]
