; expected a value @ 2:10
G1 F100 Xnan
