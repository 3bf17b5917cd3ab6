; Length of cutter compensation entry move is not greater than the tool radius @ 3:1
G41.1 D4
G1 X1 F100
