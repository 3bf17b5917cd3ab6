"""halsampler output (tag line x_um y_um z_um a_mdeg per servo period) -> CSV t,x,y,z,a,line
[s, mm, deg].

The 4-axis version of ../shared/tools/linuxcnc-sim/lcnc_raw2csv.py: the recording starts a
little before the program and ends a little after it: leading samples at the start point
(X Y Z and A) are dropped except the last (the start at rest, t = 0) and trailing samples at
the end point except the first (the end at rest); a move of A alone counts as motion. Checks
that no sample was lost.
usage: lcnc_raw2csv_a.py RAW OUT.csv STATUS.json
"""

import json
import sys

import numpy as np

TS = 1e-3  # servo period [s]


def main(raw: str, out: str, status_path: str) -> int:
    with open(raw) as f:
        rows = [r.split() for r in f if r.strip() and not r.startswith("overrun")]
    data = np.array(rows, dtype=float)
    tag, line, xyza = data[:, 0], data[:, 1].astype(int), data[:, 2:6] * 1e-3
    gaps = int(np.sum(np.diff(tag) != 1))
    moving = np.flatnonzero(np.any(np.diff(xyza, axis=0) != 0.0, axis=1))
    if len(moving) == 0:
        raise SystemExit("no motion recorded")
    i0, i1 = int(moving[0]), int(moving[-1]) + 1  # last rest sample before, first after
    xyza, line, tag = xyza[i0 : i1 + 1], line[i0 : i1 + 1], tag[i0 : i1 + 1]
    t = (tag - tag[0]) * TS
    with open(out, "w") as f:
        f.write("t,x,y,z,a,line\n")
        for ti, (x, y, z, a), li in zip(t, xyza, line):
            f.write(f"{ti:.3f},{x:.9f},{y:.9f},{z:.9f},{a:.9f},{li}\n")
    with open(status_path) as f:
        st = json.load(f)
    st.update(samples=int(len(t)), cycle_time_s=float(t[-1]), sample_gaps=gaps)
    with open(status_path, "w") as f:
        json.dump(st, f, indent=1)
    print(
        f"{out}: {len(t)} samples, cycle {t[-1]:.3f} s, gaps {gaps}, "
        f"overruns {st.get('overruns')}, errors {len(st.get('errors', []))}",
        file=sys.stderr,
    )
    return 1 if gaps or st.get("overruns") or st.get("errors") else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
