; arithmetic overflow @ 2:9
G1 F100 X[10**400]
