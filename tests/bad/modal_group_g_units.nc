; G20 and G21 are in the same modal group @ 2:5
G20 G21
