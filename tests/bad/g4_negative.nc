; negative dwell time @ 2:4
G4 P-1
