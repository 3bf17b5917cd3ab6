; o2 while without endwhile @ 2:1
o2 while [0]
G0 X1
