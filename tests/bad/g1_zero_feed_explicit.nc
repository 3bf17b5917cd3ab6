; G1 move with zero feed @ 3:1
G1 F0
X10
