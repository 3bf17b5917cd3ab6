; Cutter radius compensation allowed only in XY, XZ planes @ 2:5
G19 G41.1 D2
