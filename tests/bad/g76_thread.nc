; G76 (threading cycle, spindle-synchronised) is not supported @ 2:1
G76 P0.1 Z-10
