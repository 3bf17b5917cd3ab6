; arc turns P0 must be a positive integer @ 2:14
G3 X10 Y0 I5 P0 F100
