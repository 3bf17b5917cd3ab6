; G10 L3 is not supported @ 2:5
G10 L3 P1 Z5
