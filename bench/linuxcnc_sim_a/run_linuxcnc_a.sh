#!/bin/bash
# Run one G-code program on LinuxCNC 2.9 (uspace simulation, headless) on the 4-axis mill of
# ./config/mill_a.ini (X Y Z + A, trivkins) and write the commanded position at every 1 ms
# servo period as CSV t,x,y,z,a,line (s, mm, deg). A copy of
# ../shared/tools/linuxcnc-sim/run_linuxcnc.sh (same lock: one LinuxCNC at a time on a machine,
# whichever script starts it) for that configuration.
#   usage: [LCNC_AXIS_ACCEL=mm/s^2] run_linuxcnc_a.sh PROGRAM OUT.csv
# The config in ./config is copied to a scratch folder under ${TMPDIR:-/tmp}; LinuxCNC's own
# logs are kept next to OUT.csv (OUT.csv.log, OUT.csv.status.json).
set -euo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
prog=$(realpath "$1")
out=$(realpath -m "$2")
[[ -r $prog ]] || { echo "no program $prog" >&2; exit 2; }
mkdir -p "$(dirname "$out")"
work=$(mktemp -d "${TMPDIR:-/tmp}/lcnc-run.XXXXXX")
chmod 755 "$work"
cp -r "$HERE/config" "$work/cfg"
# optional: another acceleration limit [mm/s^2] for every linear axis, joint and TRAJ (e.g. 1732.41 =
# 2450/sqrt(2), so that the path acceleration stays under 2450 in any direction)
if [[ -n ${LCNC_AXIS_ACCEL:-} ]]; then
  sed -i -E "/^\[(AXIS_A|JOINT_3)\]/,/^$/!s/^(MAX_ACCELERATION|MAX_LINEAR_ACCELERATION|DEFAULT_LINEAR_ACCELERATION) = .*/\1 = $LCNC_AXIS_ACCEL/" "$work/cfg/mill_a.ini"
fi
mkdir -m 777 "$work/rt"   # rtapi_app's socket, created under the fallback uid
raw="$work/samples.raw"
# system python (the linuxcnc module), no X display; rtapi_app refuses root without a fallback uid
export PATH=/usr/bin:/bin:/usr/sbin:/sbin
unset DISPLAY
export RTAPI_UID=${RTAPI_UID:-65534} RTAPI_FIFO_PATH="$work/rt/.rtapi_fifo"
# a private HOME: LinuxCNC keeps its tool table in $HOME/.tool.mmap, and any other process that
# runs LinuxCNC's interpreter with the same HOME (rs274, the gcode module) recreates that file and
# kills the running task
mkdir -p "$work/home"; export HOME="$work/home"
export LCNC_PROGRAM="$prog" LCNC_RAW="$raw" LCNC_STATUS="$out.status.json"
# one LinuxCNC at a time on a machine (fixed shared-memory keys, /tmp/linuxcnc.lock): wait for
# any other instance to finish rather than let the linuxcnc script "clean it up"
# (LCNC_LOCK_HELD=1: the caller already holds that lock, e.g. bench/rotary_bench.py's batch)
if [[ -z ${LCNC_LOCK_HELD:-} ]]; then
  exec 9>"${TMPDIR:-/tmp}/linuxcnc-sim.flock"
  flock 9
fi
for _ in $(seq 600); do [[ -e /tmp/linuxcnc.lock ]] || break; sleep 1; done
[[ -e /tmp/linuxcnc.lock ]] && { echo "another LinuxCNC holds /tmp/linuxcnc.lock" >&2; exit 1; }
limit=$(( ${LCNC_TIMEOUT:-1200} + 120 ))
for attempt in 1 2; do
  rm -f "$out.status.json" "$raw"
  ( cd "$work/cfg" && timeout -k 30 "$limit" linuxcnc "$work/cfg/mill_a.ini" 9>&- ) </dev/null >"$out.log" 2>&1 || true
  # linuxcnc sends its own output to temp files when it has no tty; on failure it copies them here
  for f in "$HOME/linuxcnc_debug.txt" "$HOME/linuxcnc_print.txt"; do
    [[ -f $f && $f -nt $work ]] && { echo "== $f"; cat "$f"; } >>"$out.log" || true
  done
  if [[ -s $raw && -f $out.status.json ]] && ! grep -q '"program did not start' "$out.status.json"; then
    break
  fi
  echo "LinuxCNC attempt $attempt failed for $prog (see $out.log)" >&2
done
if [[ ! -s $raw || ! -f $out.status.json ]]; then
  echo "LinuxCNC run failed for $prog (see $out.log)" >&2; tail -20 "$out.log" >&2; exit 1
fi
/usr/bin/python3 "$HERE/lcnc_raw2csv_a.py" "$raw" "$out" "$out.status.json"
rm -rf "$work"
