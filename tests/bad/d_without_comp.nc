; D word with no G41/G42 to use it @ 2:4
G0 D1 X1
