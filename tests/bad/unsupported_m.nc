; M100: no executable named M100 in the user M-code path @ 2:1
M100
