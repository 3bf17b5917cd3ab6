; Q word missing with g83 @ 2:1
G83 X1 Y1 Z-1 R1 F100
