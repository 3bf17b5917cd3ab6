; M62 is not supported @ 2:1
M62 P1
