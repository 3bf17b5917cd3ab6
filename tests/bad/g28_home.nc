; G28 (return to home) is not supported @ 2:1
G28
