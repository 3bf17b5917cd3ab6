; o2 repeat without endrepeat @ 2:1
o2 repeat [2]
G0 X1
