; O100 without a keyword @ 3:1
G0 X1
O100
