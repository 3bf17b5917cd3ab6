; G7 (lathe diameter mode) is not supported @ 2:1
G7
