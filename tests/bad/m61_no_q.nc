; M61 needs a Q word @ 2:1
M61
M2
