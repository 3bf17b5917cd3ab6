; o3 break outside a loop @ 2:1
o3 break
