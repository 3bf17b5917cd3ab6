; expected a value @ 2:6
G1 X Y2 F100
