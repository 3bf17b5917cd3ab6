; tool number T1.5 @ 2:1
T1.5
