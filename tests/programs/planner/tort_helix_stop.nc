; tort.ngc (LinuxCNC's nc_files) lines 99-101: a 56.6 mm helix at F500 that stops into an
; arc of another plane. Planned under LinuxCNC's limits (bench/programs/linuxcnc_limits.toml).
G21 G90 G94
G0 X-5.872598 Y11.985548 Z10.305119
G17 G2 F500 I2.329371 J-8.693332 X-5.872598 Y11.985548 Z7.805119
G19 G3 J2.897777 K0.776457 X-3.872598 Y17.004646 Z6.460255
M2
