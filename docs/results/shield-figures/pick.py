"""The rule of docs/results/shield-figures/run.sh, fixed before any result: among the shield figures
evaluated on the validation episodes for one set of networks (3 seeds), keep those whose mean
survival is at least 97 % in both settings and print the one ("GAP DECEL") with the highest mean
achievement over both settings (a tie: the first, the driver's figures first)::

    python pick.py VALIDATION_DIR NETWORK_PREFIX

Room: a diagnostic script beside its results (run by path, not installed). May import: the standard library.
"""
import json
import sys
from pathlib import Path

out, net = Path(sys.argv[1]), sys.argv[2]
best = None
for gap, decel in (("3.0", "0.9"), ("2.0", "1.0"), ("2.0", "0.9")):
    runs = {lane: [out / f"{net}-seed{s}-gap{gap}-decel{decel}-{lane}.json" for s in range(3)]
            for lane in ("random", "non-target")}
    if not all(f.is_file() for fs in runs.values() for f in fs):
        continue
    rates = {lane: [json.loads(f.read_text()) for f in fs] for lane, fs in runs.items()}
    survival = [sum(r["survival_rate"] for r in rs) / 3 for rs in rates.values()]
    achievement = sum(r["achievement_rate"] for rs in rates.values() for r in rs) / 6
    if min(survival) >= 0.97 and (best is None or achievement > best[0]):
        best = (achievement, f"{gap} {decel}")
print(best[1] if best else "3.0 0.9")
