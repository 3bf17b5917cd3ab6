; P must be an integer 0..9 @ 2:8
G10 L2 P10 X5
