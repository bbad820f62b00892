"""Phase 2's updates and env steps a second from `laneshift train` progress lines, from 20 s after
phase 2's first line to the last line (what tp.sh's runs are compared on):

    python3 rates.py OUT_DIR/tp-*.log

Room: a study script (docs/results). May import: the standard library.
"""

from __future__ import annotations

import re
import sys

LINE = re.compile(r"\[\s*([\d.]+)s\] steps\s+([\d,]+)/.*upd\s+([\d,]+) .* phase (\d)")

for path in sys.argv[1:]:
    rows = []
    for line in open(path):
        m = LINE.match(line)
        if m:
            rows.append((float(m[1]), int(m[2].replace(",", "")), int(m[3].replace(",", "")), int(m[4])))
    phase2 = [r for r in rows if r[3] == 2]
    window = [r for r in phase2 if r[0] >= phase2[0][0] + 20]
    (t0, s0, u0, _), (t1, s1, u1, _) = window[0], window[-1]
    print(f"{path}: phase 2, {t0:.0f}-{t1:.0f} s: {(u1 - u0) / (t1 - t0):.1f} upd/s, "
          f"{(s1 - s0) / (t1 - t0):.0f} env steps/s")
