; polar coordinates (@ ^) are only allowed in the XY plane @ 2:13
G18 G1 F100 @5 ^30
