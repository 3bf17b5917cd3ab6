; E word with no M66, M67 or M68 to use it @ 2:11
G1 F100 X1e3
