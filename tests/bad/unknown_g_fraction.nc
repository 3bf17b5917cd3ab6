; unknown G code G1.7 @ 2:1
G1.7 X1
