; not finite @ 2:9
G1 F100 X[SIN[10**200 * 10**200]]
