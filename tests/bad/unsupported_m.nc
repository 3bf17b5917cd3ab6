; M99 is not supported @ 2:1
M99
