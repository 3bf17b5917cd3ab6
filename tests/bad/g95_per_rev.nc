; G95 feed per revolution with spindle speed S0 @ 2:1
G95 G1 X1 F0.1
