; Cannot use inverse time feed with canned cycles @ 3:5
G21 G0 Z5
G93 G81 X1 Y1 Z-1 R1 F10
