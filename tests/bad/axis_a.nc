; the machine has no A axis @ 2:9
G1 F100 A10
