; arc turns P1e+09 is out of range @ 2:15
F1 G3 X0 I0.5 P1000000000
