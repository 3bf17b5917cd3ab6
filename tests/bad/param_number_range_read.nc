; #0 out of range @ 2:9
G1 F100 X#0
