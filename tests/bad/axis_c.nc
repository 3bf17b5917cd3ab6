; axis C is not supported @ 2:4
G0 C5
