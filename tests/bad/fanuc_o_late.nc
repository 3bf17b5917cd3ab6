; O1000 without a keyword @ 4:1
O0001 (MAIN)
G0 X1
O1000
