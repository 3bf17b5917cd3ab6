; unclosed comment @ 2:12
G1 F100 X1 (no end
