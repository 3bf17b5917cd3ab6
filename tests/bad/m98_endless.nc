; nested calls @ 6:1
G0 X1
M98 P1
M2
O1
M98 P1
M99
