; the machine has no A axis @ 3:7
G91 G0 A0 X1
G0 X1 A-0.5
