; M3 and M4 are in the same modal group @ 2:4
M3 M4 S1000
