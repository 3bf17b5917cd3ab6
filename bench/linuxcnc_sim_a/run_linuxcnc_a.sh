#!/bin/bash
# Run one G-code program on LinuxCNC 2.9 (uspace simulation, headless) on the 4-axis mill of
# ./config/mill_a.ini (X Y Z + A, trivkins) and write the commanded position at every 1 ms
# servo period as CSV t,x,y,z,a,line (s, mm, deg): bench/linuxcnc_sim/run_linuxcnc.sh (its
# driver, lock and options: LCNC_AXIS_ACCEL for the linear axes, LCNC_LOCK_HELD, LCNC_TIMEOUT)
# with this folder's machine and converter.
#   usage: [LCNC_AXIS_ACCEL=mm/s^2] run_linuxcnc_a.sh PROGRAM OUT.csv
set -euo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
LCNC_SIM_CONFIG="$HERE/config" LCNC_SIM_INI=mill_a.ini LCNC_SIM_RAW2CSV="$HERE/lcnc_raw2csv_a.py" \
  exec "$HERE/../linuxcnc_sim/run_linuxcnc.sh" "$@"
