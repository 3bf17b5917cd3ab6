; LN of a non-positive number @ 2:9
G1 F100 X[LN[0]]
