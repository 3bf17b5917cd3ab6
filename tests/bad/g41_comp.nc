; G41 (cutter radius compensation) is not supported @ 3:1
G41 D1
G1 X1 F100
