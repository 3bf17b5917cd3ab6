; o101 if without endif @ 3:1
#1 = 0
O101 if [#1 GT 0]
G1 X1 F100
