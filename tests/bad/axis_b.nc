; the machine has no B axis @ 2:4
G0 B5
