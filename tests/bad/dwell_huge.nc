; dwell P1e+07 is out of range @ 2:4
G4 P10000000
