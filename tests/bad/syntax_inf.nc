; expected a value @ 2:11
G1 F100 X-inf
