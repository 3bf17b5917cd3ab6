; G53 needs G0 or G1 @ 2:1
G53 X1
