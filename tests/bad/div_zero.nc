; division by zero @ 3:9
#1=0
G1 F100 X[2/#1]
