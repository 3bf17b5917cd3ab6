; M72 with no state saved by M70 @ 3:1
G0 X1
M72
