; G93 (inverse time) moves need an F word on every line @ 3:1
G93 G1 X1 F2
X2
