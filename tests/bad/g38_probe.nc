; G38.2 (probing needs a probe input) is not supported @ 2:1
G38.2 Z-10 F100
