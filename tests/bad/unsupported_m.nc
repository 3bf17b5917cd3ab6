; M100 is not supported @ 2:1
M100
