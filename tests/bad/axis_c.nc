; the machine has no C axis @ 3:8
G91 G0 C0
G90 G0 C5
