; neither R nor I/J/K @ 2:4
G3 X10 Y0 F100
