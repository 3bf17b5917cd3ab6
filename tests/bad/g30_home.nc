; G30 (return to second home) is not supported @ 2:1
G30 Z10
