; M98 needs a P word @ 2:1
M98 L2
M2
