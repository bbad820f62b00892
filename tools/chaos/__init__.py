"""``laneshift chaos``: the fault suite. Each fault against a real 2-worker local run.

What it is: one training run per fault, each with the fault injected at a fixed point of the
run, and one table row per fault: survived, recovery seconds, transitions made / stored /
counted lost, weights versions monotonic, demo shard bytes identical, processes left behind.
``tests/test_faults.py`` runs the same faults (with ``strikes.FaultInjector``) as fast tests.

    laneshift chaos --faults worker,learner,router,replay,replay-after-checkpoint,replay-during-checkpoint --json
    laneshift chaos --faults disk-full,unwritable,stats-flood,launcher-sigterm,launcher-kill

The link rows (``link-reset``, ``link-cut``, ``slow-link``) put a TCP proxy (``linkproxy``) between
the workers and the router; a cut between two hosts (two network namespaces, root) runs as
``pytest -m chaos tests/test_network_faults.py``.

The pieces: this module (the command and its table), ``faults`` (the faults and the run they
strike), ``strikes`` (the threads that strike a running run and time its recovery) and ``runs``
(one run of each fault, and its row).

Room: the tools (the fault suite, beside the wiring it strikes). May import: the contract and ``deploy``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from .faults import FAULTS
from .runs import run_fault


def render(rows: list[dict]) -> str:
    head = f"{'fault':<26}{'survived':>9}{'recovery s':>11}{'made':>8}{'stored':>8}{'lost':>6}{'unacc.':>7}" \
           f"{'monotonic':>10}{'demo same':>10}{'left':>5}"
    lines = [head]
    for r in rows:
        lines.append(f"{r['fault']:<26}{str(r.get('survived')):>9}{str(r.get('recovery_s')):>11}"
                     f"{r.get('made', '-'):>8}{r.get('stored', '-'):>8}{r.get('lost_counted', '-'):>6}"
                     f"{r.get('unaccounted', '-'):>7}{str(r.get('versions_monotonic')):>10}"
                     f"{str(r.get('demo_identical')):>10}{r.get('left_behind', '-'):>5}")
    return "\n".join(lines)


def chaos_main(args: argparse.Namespace) -> int:
    names = [n.strip() for n in args.faults.split(",") if n.strip()]
    unknown = [n for n in names if n not in FAULTS]
    if unknown:
        print(f"laneshift chaos: unknown fault {unknown[0]!r} (known: {', '.join(FAULTS)})", file=sys.stderr)
        return 2
    work = Path(args.work_dir).resolve()
    demos = None
    if args.demos:
        from laneshift.tools.demos.generate import generate_shard

        shard = work / "demos"
        demos = str(shard) if any(shard.glob("**/metadata.json")) else \
            str(generate_shard(shard, env_id_or_scenario="lka", env_kwargs={}, episodes=6, seed=0))
    rows = []
    for name in names:
        print(f"chaos: {name} ...", file=sys.stderr, flush=True)
        rows.append(run_fault(name, work, args.env_steps, demos))
        print(f"chaos: {name}: {'survived' if rows[-1].get('survived') else 'FAILED'}, "
              f"recovery {rows[-1].get('recovery_s')} s", file=sys.stderr, flush=True)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    result = {"revision": rev, "env_steps": args.env_steps, "rows": rows}
    if args.out:  # Ray's raylet may print its own lines to stdout: a file holds the JSON alone
        Path(args.out).write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2) if args.json else render(rows))
    return 0 if all(r.get("survived") for r in rows) else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("chaos", help="the fault suite: each fault against a real 2-worker local run, one row each")
    p.add_argument("--faults", default=",".join(FAULTS), help=f"comma-separated (default: all of {', '.join(FAULTS)})")
    p.add_argument("--env-steps", type=int, default=8000, help="budget of each run (default 8000)")
    p.add_argument("--work-dir", default="runs/chaos", help="where the runs go (default runs/chaos)")
    p.add_argument("--demos", action="store_true", help="retention with a demo shard, to check its bytes stay identical")
    p.add_argument("--json", action="store_true", help="print the rows as one JSON object instead of a table")
    p.add_argument("--out", help="also write the JSON result to this file")
    p.set_defaults(func=chaos_main)
