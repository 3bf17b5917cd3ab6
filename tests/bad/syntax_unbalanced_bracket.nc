; unexpected end of line @ 3:18
G0 X0
G1 F100 X[[1 + 2]
