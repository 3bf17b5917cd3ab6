; G33 (spindle-synchronised motion) is not supported @ 2:1
G33 X1 K0.1
