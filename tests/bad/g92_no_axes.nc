; G92 needs at least one axis word @ 2:1
G92
