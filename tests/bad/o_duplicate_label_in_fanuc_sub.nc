; duplicate O-word label o101 @ 9:1
G21 G90
M98 P100
M30
O100
o101 repeat [1]
G1 X1 F100
o101 endrepeat
o101 repeat [1]
G1 X0
o101 endrepeat
M99
