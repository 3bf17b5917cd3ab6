; below the resolution of the depth @ 2:1
G83 Z0.99999999999 R1 Q0.00000000000000005 F100
M2
