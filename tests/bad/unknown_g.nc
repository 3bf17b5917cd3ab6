; unknown G code G15 @ 2:1
G15
