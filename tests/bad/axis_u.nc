; axis U is not supported @ 2:4
G0 U1
