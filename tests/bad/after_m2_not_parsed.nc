; unexpected character @ 3:10
G1 F100 X1
G1 X2 Y3 $
M2
%% trailer ((( $ garbage after M2 is never read
