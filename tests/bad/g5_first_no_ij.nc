; G5 needs I and J unless it follows another G5 @ 2:1
G5 F100 X1 Y1 P1 Q0
