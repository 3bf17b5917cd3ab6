; computed O label (o#… or o[…]) only works with call @ 3:1
#1 = 4
o#1 sub
G0 X1
o4 endsub
M2
