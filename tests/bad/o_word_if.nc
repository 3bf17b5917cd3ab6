; O-words @ 3:1
#1 = 1
O101 if [#1 GT 0]
