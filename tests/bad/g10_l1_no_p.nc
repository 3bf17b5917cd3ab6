; G10 L1 needs P @ 2:1
G10 L1 Z5
