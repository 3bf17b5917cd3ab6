; G1 move with zero feed @ 2:1
G1 X10
