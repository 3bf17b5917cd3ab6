; Bad character '%' used @ 4:1
G0 X1
G1 Y1 F100
%
