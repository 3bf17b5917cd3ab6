; N (line number) must start the line @ 2:7
G1 X1 N10 F100
