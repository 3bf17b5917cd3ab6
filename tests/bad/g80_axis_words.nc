; axis words with G80 @ 2:1
G80 X1
