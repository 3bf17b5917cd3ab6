; #6000 out of range @ 2:1
#6000 = 1
