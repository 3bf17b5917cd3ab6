; G10 needs an L word @ 2:1
G10 P1 X5
