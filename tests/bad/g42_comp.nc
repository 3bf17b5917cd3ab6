; G42 (cutter radius compensation) is not supported @ 2:1
G0 X1 G42
