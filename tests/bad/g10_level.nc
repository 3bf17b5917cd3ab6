; G10 L1 is not supported @ 2:5
G10 L1 P1 Z5
