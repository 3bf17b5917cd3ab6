; M250 is not supported @ 2:1
M250
