; R less than z in cycle in xy plane @ 2:1
G81 X1 Y1 Z1 R-1 F100
