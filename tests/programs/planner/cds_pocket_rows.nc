; cds.ngc (LinuxCNC's nc_files, "Circle Diamond Square Program", Tom Kramer) lines 11-24:
; the first rows of its pocket, F16 (inches). Planned under LinuxCNC's limits
; (bench/programs/linuxcnc_limits.toml).
G20 G90
F16.0
G0 Z2.1
G0 X0.0 Y3.915
G1 Z1.6875
G1 X4.0
G1 Y3.725
G1 X0.0
G1 Y3.535
G1 X1.437
G3 X1.0704 Y3.345 R1.635
G1 X0.0
G1 Y3.155
M2
