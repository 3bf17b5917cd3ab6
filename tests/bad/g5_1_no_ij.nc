; G5.1 needs both I and J @ 2:1
G5.1 F100 X1 Y1 I1
