; cannot turn cutter compensation on when it is already on @ 3:1
G41 D1
G42 D1
