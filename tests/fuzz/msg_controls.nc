G21 G90
(MSG,]0;pwned[2J)
(DEBUG, ›31m red)
G1 X1 Y1 F600
M2
