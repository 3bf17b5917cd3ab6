; G5.3 without G5.2 @ 2:1
G5.3
