; G4 dwell needs a P word @ 2:1
G4
