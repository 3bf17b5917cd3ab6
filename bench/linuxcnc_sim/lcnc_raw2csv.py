"""halsampler output (tag line x_um y_um z_um per servo period) -> CSV t,x,y,z,line [s, mm].

The recording starts a little before the program and ends a little after it: leading samples
at the start point are dropped except the last (the start at rest, t = 0) and trailing samples
at the end point except the first (the end at rest). Checks that no sample was lost.
usage: lcnc_raw2csv.py RAW OUT.csv STATUS.json
"""

import json
import sys

import numpy as np

TS = 1e-3  # servo period [s]

raw, out, status_path = sys.argv[1:4]
rows = [l.split() for l in open(raw) if l.strip() and not l.startswith("overrun")]
a = np.array(rows, dtype=float)
tag, line, xyz = a[:, 0], a[:, 1].astype(int), a[:, 2:5] * 1e-3
gaps = int(np.sum(np.diff(tag) != 1))
step = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
moving = np.flatnonzero(step > 0)
if len(moving) == 0:
    raise SystemExit("no motion recorded")
i0, i1 = int(moving[0]), int(moving[-1]) + 1  # last rest sample before, first rest sample after
xyz, line, tag = xyz[i0 : i1 + 1], line[i0 : i1 + 1], tag[i0 : i1 + 1]
t = (tag - tag[0]) * TS
with open(out, "w") as f:
    f.write("t,x,y,z,line\n")
    for ti, (x, y, z), li in zip(t, xyz, line):
        f.write(f"{ti:.3f},{x:.9f},{y:.9f},{z:.9f},{li}\n")
st = json.load(open(status_path))
st.update(samples=int(len(t)), cycle_time_s=float(t[-1]), sample_gaps=gaps)
json.dump(st, open(status_path, "w"), indent=1)
print(
    f"{out}: {len(t)} samples, cycle {t[-1]:.3f} s, gaps {gaps}, overruns {st.get('overruns')}, "
    f"errors {len(st.get('errors', []))}",
    file=sys.stderr,
)
if gaps or st.get("overruns") or st.get("errors"):
    sys.exit(1)
