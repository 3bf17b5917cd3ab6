; polar coordinates (@ ^) with X @ 2:12
G1 F100 @5 X1
