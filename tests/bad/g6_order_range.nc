; order P9 must be an integer in 2..8 @ 3:6
F100
G6.2 P9 K0 X0 Y0 R1
