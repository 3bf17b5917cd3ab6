; needs P<order> @ 3:1
F100
G6.2 K0 X0 Y0 R1
