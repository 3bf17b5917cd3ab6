; arc move with zero feed @ 2:4
G2 X10 Y0 I5
