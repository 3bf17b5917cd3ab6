; G53 cannot be used with G91 @ 2:5
G91 G53 G0 X1
