; rotary axis motion is not supported @ 2:4
G0 B5
