; rotary axis motion is not supported @ 2:9
G1 F100 A10
