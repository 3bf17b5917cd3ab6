; 20 mm square under G61 (exact path) at F1000 (planner v2 monotonicity check)
G21 G17 G90 G94 G61
G0 X0 Y0
G1 X20 Y0 F1000
G1 X20 Y20
G1 X0 Y20
G1 X0 Y0
M2
