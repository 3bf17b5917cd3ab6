; G28 with cutter compensation on @ 3:1
G41.1 D2
G28
