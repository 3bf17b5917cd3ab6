; G41 (cutter radius compensation) is not supported @ 2:1
G41 D1
