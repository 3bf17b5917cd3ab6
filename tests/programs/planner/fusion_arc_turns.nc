; fusion360_1110_wall_265bit.nc (the corpus's Fusion 360 2D pocket) lines 1074-1079: a
; 17 mm line, a 20 mm arc (r 12.8 mm) turning through a 0.24 mm arc into a 9.8 mm line and
; out through another into a 20 mm arc, all tangent, at F1000. Planned under LinuxCNC's
; limits (bench/programs/linuxcnc_limits.toml).
G21 G90 G94 G17
G0 X3.185 Y0 Z-5.95
G1 Y17.144 F1000
G2 X16.977 Y29.876 I12.773 J0
G3 X17.23 Y30.111 I0.018 J0.235
G1 Y39.889
G3 X16.977 Y40.124 I-0.235 J0
G2 X3.185 Y52.856 I-0.98 J12.774
G1 Y60
M2
