; H word with no G43 @ 2:7
G0 X1 H1
