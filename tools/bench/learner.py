"""`laneshift bench learner`: learner updates/s, the real update against a bare torch loop.

Two implementations of one Double DQN update are timed side by side, alternating A B A B
(``--rounds`` rounds of ``--seconds`` each, after a warm-up), for each case:

- **DoubleDQN.update** (``learner/dqn.py``): the learner's own update, fed exactly as the learner
  feeds it: a ``wire.SampledBatch`` of ``learner.prefetch`` batches, encoded and decoded through the
  wire (``wire.encode_batch`` / ``wire.decode_batch``, once, outside the timing) and split per update
  with the learner loop's ``split_updates``; numpy in, so every update turns its batch into tensors (shared
  on CPU, copied to a GPU) and computes its metrics and |TD error|; like the learner loop, it reads
  none of them back per update (the loop reads the metrics once per log interval, and the |TD
  errors| once per sample reply only from a prioritized replay; this batch is uniform).
- **bare torch**: the same network (``build_q_network``), batch, Adam (fused, as the learner's),
  Huber loss, global-norm gradient
  clipping, Double DQN target and hard target sync, with the batches already on the device and
  nothing read back: the plain-torch figure the learner is measured against.

Each measurement also records the process's CPU time (``updates_per_cpu_s``): with one torch
thread on a CPU shared with other work it is steadier than wall time, and the table shows both
ratios.

Cases: the vector default (MLP, obs (82,) float32, hidden (256, 256), 9 actions, batch 256), the
allroads network's 512 x 512 trunk (obs (96,)), and
the Nature CNN that grayscale observations (4 x 100 x 100 uint8) select, at batch 32 and 64.
Hyperparameters are ``LearnerConfig``'s defaults; ``torch.set_num_threads`` is the learner's
``learner.torch_threads`` (1) unless ``--threads`` says otherwise. On cuda each measurement is
bracketed by ``torch.cuda.synchronize()``.

    laneshift bench learner                          # auto device, text table
    laneshift bench learner --device cuda --json     # one JSON object

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import platform
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from laneshift import wire

# torch is imported inside the functions that measure: every `laneshift` command builds its parser
# with this module's register(), and a module-level import cost each of them ~2 s.
from laneshift.config import LearnerConfig
from laneshift.cpus import has_bf16_instructions

N_ACTIONS = 9


@dataclass(frozen=True)
class Case:
    name: str
    obs_shape: tuple[int, ...]
    obs_dtype: str
    batch: int
    cnn: str = "nature"  # learner.cnn, for image observations
    precision: str = "fp32"  # learner.cnn_precision (image observations) or learner.mlp_precision (vectors)
    hidden: tuple[int, ...] | None = None  # learner.hidden (None: the default)
    rows: str = ""  # learner.cnn_rows (image observations; "": the whole frame)


CASES = (
    Case("mlp-b256", (82,), "float32", 256),  # env.observation=vector, the default
    Case("mlp512-b256", (96,), "float32", 256, hidden=(512, 512)),  # the allroads network's trunk
    Case("mlp-b256-bf16", (82,), "float32", 256, precision="bf16"),  # learner.mlp_precision=bf16
    Case("mlp512-b256-bf16", (96,), "float32", 256, precision="bf16", hidden=(512, 512)),
    Case("cnn-b32", (4, 100, 100), "uint8", 32),  # env.observation=grayscale (the paper's)
    Case("cnn-b64", (4, 100, 100), "uint8", 64),
    Case("small-b32", (4, 100, 100), "uint8", 32, "small"),  # learner.cnn=small: the pixel runs' network
    Case("small-b64", (4, 100, 100), "uint8", 64, "small"),
    Case("small-b32-bf16", (4, 100, 100), "uint8", 32, "small", "bf16"),  # learner.cnn_precision=bf16
    Case("small-b32-bf16-rows", (4, 100, 100), "uint8", 32, "small", "bf16", rows="22:78"),  # learner.cnn_rows
    Case("small-b32-rows", (4, 100, 100), "uint8", 32, "small", rows="22:78"),  # the same in float32
    Case("small-b128", (4, 100, 100), "uint8", 128, "small"),  # the GPU pixel study's batch
    Case("small-b128-bf16", (4, 100, 100), "uint8", 128, "small", "bf16"),
)


# ----------------------------------------------------------------------------- CLI


def register(subparsers: Any) -> None:
    """Add the ``learner`` sub-command (the cli calls this under ``laneshift bench``)."""
    p = subparsers.add_parser("learner", help="learner updates/s: DoubleDQN.update vs a bare torch loop (MLP, CNN)")
    _add_arguments(p)
    p.set_defaults(func=run)


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="auto (cuda when torch sees a GPU), cpu or cuda (default auto)")
    p.add_argument("--seconds", type=float, default=3.0, help="seconds per measurement (default 3)")
    p.add_argument("--rounds", type=int, default=2, help="A B rounds per case, at least 2 (default 2)")
    p.add_argument("--warmup", type=float, default=0.5,
                   help="seconds of warm-up per implementation and case, at least 2 updates (1 with 0; default 0.5)")
    p.add_argument("--threads", type=int, default=LearnerConfig.torch_threads,
                   help="torch.set_num_threads (default: learner.torch_threads, 1; 0 keeps torch's own)")
    p.add_argument("--cases", default=",".join(c.name for c in CASES),
                   help=f"comma-separated subset of {','.join(c.name for c in CASES)} (default all)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")


def run(args: argparse.Namespace) -> int:
    if args.seconds <= 0 or args.warmup < 0 or args.rounds < 2 or args.threads < 0:
        raise SystemExit("bench learner: --seconds must be > 0, --warmup >= 0, --rounds >= 2, --threads >= 0")
    names = [n.strip() for n in args.cases.split(",") if n.strip()]
    known = {c.name: c for c in CASES}
    if not names or any(n not in known for n in names):
        raise SystemExit(f"bench learner: --cases takes names from {','.join(known)}, got {args.cases!r}")
    try:
        result = bench(args.device, seconds=args.seconds, rounds=args.rounds, warmup=args.warmup,
                       threads=args.threads, cases=[known[n] for n in names],
                       log=sys.stderr if args.json else sys.stdout)
    except ValueError as exc:  # learner.device=cuda without a GPU
        print(f"bench learner: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result) if args.json else format_result(result))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="laneshift bench learner", description=__doc__.splitlines()[0])
    _add_arguments(parser)
    return run(parser.parse_args(argv))


# ----------------------------------------------------------------------------- batches


def _split(batch: wire.SampledBatch) -> list[dict[str, np.ndarray]]:
    """The learner loop's split of a SampledBatch into update batches (``learner.batches``)."""
    from laneshift.learner.batches import split_updates

    return split_updates(batch)


def sampled_batch(case: Case, num_batches: int, seed: int = 0) -> wire.SampledBatch:
    """What the replay server answers a ``SampleRequest(case.batch, num_batches)`` with, after the
    wire: field dtypes as ``ReplayCore._gather`` makes them, uniform sampling (weights 1), no demos."""
    rng = np.random.default_rng(seed)
    n = case.batch * num_batches
    shape = (n, *case.obs_shape)
    if case.obs_dtype == "uint8":
        obs, next_obs = (rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(2))
    else:
        obs, next_obs = (rng.standard_normal(shape, dtype=np.float32) for _ in range(2))
    batch = wire.SampledBatch(
        obs=obs, next_obs=next_obs, action=rng.integers(0, N_ACTIONS, n).astype(np.int64),
        reward=rng.standard_normal(n, dtype=np.float32), terminated=(rng.random(n) < 0.02).astype(np.uint8),
        steps=np.ones(n, np.uint8), is_demo=np.zeros(n, np.uint8), index=np.arange(n, dtype=np.int64),
        weight=np.ones(n, np.float32), num_batches=num_batches, info={"phase": 0, "prioritized": False})
    schema = wire.TransitionSchema(obs_shape=case.obs_shape, obs_dtype=np.dtype(case.obs_dtype).str,
                                   n_actions=N_ACTIONS)
    return wire.decode_batch(wire.encode_batch(batch), schema)


# ----------------------------------------------------------------------------- the two implementations


def learner_step(case: Case, cfg: LearnerConfig) -> tuple[Callable[[], None], torch.nn.Module, torch.device]:
    """One ``DoubleDQN.update`` per call, cycling over the parts of one decoded SampledBatch."""
    from laneshift.learner.dqn import DoubleDQN

    agent = DoubleDQN(case.obs_shape, N_ACTIONS, _case_config(case, cfg))
    parts = _split(sampled_batch(case, cfg.prefetch))
    state = {"i": 0}

    def step() -> None:
        agent.update(parts[state["i"] % len(parts)])
        state["i"] += 1

    return step, agent.online, agent.device


def _case_config(case: Case, cfg: LearnerConfig) -> LearnerConfig:
    image = len(case.obs_shape) == 3
    return dataclasses.replace(cfg, cnn=case.cnn, cnn_precision=case.precision if image else "fp32",
                               mlp_precision="fp32" if image else case.precision, hidden=case.hidden or cfg.hidden,
                               cnn_rows=case.rows)


def bare_step(case: Case, cfg: LearnerConfig, device: torch.device) -> Callable[[], None]:
    """The same update in plain torch, batches resident on the device, nothing read back."""
    import torch
    import torch.nn.functional as F
    from laneshift.qnet import build_q_network

    cfg = _case_config(case, cfg)

    torch.manual_seed(cfg.seed)
    online = build_q_network(case.obs_shape, N_ACTIONS, cfg.hidden, cfg.dueling, cfg.network_cnn, cfg.cnn_precision,
                             mlp_precision=cfg.mlp_precision).to(device)
    target = copy.deepcopy(online).requires_grad_(False)
    # The learner's optimizer (fused Adam, learner/dqn.py): "the same optimizer" is the fair bar.
    opt = torch.optim.Adam(online.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, fused=device.type in ("cpu", "cuda"))
    parts = []
    for p in _split(sampled_batch(case, cfg.prefetch, seed=1)):
        parts.append({
            "obs": torch.tensor(p["obs"], device=device), "next_obs": torch.tensor(p["next_obs"], device=device),
            "action": torch.tensor(p["action"], dtype=torch.int64, device=device),
            "reward": torch.tensor(p["reward"], dtype=torch.float32, device=device),
            "not_done": 1.0 - torch.tensor(p["terminated"], dtype=torch.float32, device=device),
            "steps": torch.tensor(p["steps"], dtype=torch.float32, device=device),
            "weight": torch.tensor(p["weight"], dtype=torch.float32, device=device)})
    state = {"i": 0}

    def step() -> None:
        b = parts[state["i"] % len(parts)]
        q = online(b["obs"]).gather(1, b["action"][:, None]).squeeze(1)
        with torch.no_grad():
            next_action = online(b["next_obs"]).argmax(dim=1, keepdim=True)
            next_q = target(b["next_obs"]).gather(1, next_action).squeeze(1)
            td_target = b["reward"] + torch.pow(cfg.gamma, b["steps"]) * b["not_done"] * next_q
        loss = (b["weight"] * F.huber_loss(q, td_target, reduction="none", delta=cfg.huber_delta)).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(online.parameters(), cfg.grad_clip)
        opt.step()
        state["i"] += 1
        if state["i"] % cfg.target_update_period == 0:
            target.load_state_dict(online.state_dict())

    return step


# ----------------------------------------------------------------------------- timing


def _sync(device: torch.device) -> None:
    import torch
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure(step: Callable[[], None], seconds: float, device: torch.device, min_updates: int = 1) -> dict:
    """Updates until ``seconds`` passed (at least ``min_updates``); the clock stops after a sync."""
    _sync(device)
    t0, c0 = time.perf_counter(), time.process_time()
    n = 0
    while n < min_updates or time.perf_counter() - t0 < seconds:
        step()
        n += 1
    _sync(device)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"updates": n, "wall_s": wall, "updates_per_s": n / wall, "cpu_s": cpu,
            "updates_per_cpu_s": n / cpu if cpu > 0 else None}


def device_name(device: torch.device) -> str:
    import torch
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def bench(device: str = "auto", *, seconds: float = 3.0, rounds: int = 2, warmup: float = 0.5, threads: int = 1,
          cases: list[Case] | tuple[Case, ...] = CASES, log=None) -> dict:
    """Every figure of the benchmark as one JSON-ready dict."""
    import torch
    from laneshift.learner.dqn import resolve_device

    dev = resolve_device(device)
    cfg = LearnerConfig(device=dev.type)
    threads_before = torch.get_num_threads()
    if threads:
        torch.set_num_threads(threads)
    try:
        out_cases = []
        for case in cases:
            if log is not None:
                print(f"bench learner: {case.name} on {dev} ...", file=log, flush=True)
            impls: dict[str, Callable[[], None]] = {}
            impls["learner"], online, _ = learner_step(case, cfg)
            impls["bare"] = bare_step(case, cfg, dev)
            for step in impls.values():
                measure(step, warmup, dev, min_updates=2 if warmup > 0 else 1)
            per_round: dict[str, list[dict]] = {k: [] for k in impls}
            for _ in range(rounds):  # A B A B: drift (clocks, heat, other load) hits both alike
                for name, step in impls.items():
                    per_round[name].append(measure(step, seconds, dev))
            row: dict[str, Any] = {
                "name": case.name, "network": type(online).__name__, "precision": case.precision,
                "obs_shape": list(case.obs_shape), "rows": case.rows,
                "obs_dtype": case.obs_dtype, "batch": case.batch, "n_actions": N_ACTIONS,
                "hidden": list(_case_config(case, cfg).hidden),
                "params": sum(p.numel() for p in online.parameters())}
            for name, runs in per_round.items():
                rates = [r["updates_per_s"] for r in runs]
                row[name] = {"updates_per_s": statistics.fmean(rates), "min": min(rates), "max": max(rates),
                             "rows_per_s": statistics.fmean(rates) * case.batch, "rounds": runs}
            row["learner_over_bare"] = row["learner"]["updates_per_s"] / row["bare"]["updates_per_s"]
            # The same ratio from CPU time (all rounds pooled): steadier than wall time on a shared CPU.
            cpu = {k: sum(r["cpu_s"] for r in runs) for k, runs in per_round.items()}
            ups = {k: sum(r["updates"] for r in runs) for k, runs in per_round.items()}
            row["learner_over_bare_cpu"] = (ups["learner"] / cpu["learner"]) / (ups["bare"] / cpu["bare"]) \
                if cpu["learner"] > 0 and cpu["bare"] > 0 else None
            out_cases.append(row)
            del impls, online
            if dev.type == "cuda":
                torch.cuda.empty_cache()
        return {
            "device": dev.type, "device_name": device_name(dev), "torch": torch.__version__,
            "cpu_bf16": has_bf16_instructions() if dev.type == "cpu" else None,
            "cuda": torch.version.cuda if dev.type == "cuda" else None, "threads": torch.get_num_threads(),
            "python": platform.python_version(), "seconds": seconds, "rounds": rounds, "warmup_s": warmup,
            "prefetch": cfg.prefetch, "hidden": list(cfg.hidden), "cases": out_cases}
    finally:
        torch.set_num_threads(threads_before)


def format_result(r: dict) -> str:
    bf16 = {True: ", bfloat16 instructions", False: ", no bfloat16 instructions (bf16 cases emulated)"}
    head = (f"laneshift bench learner: {r['device']} ({r['device_name']}{bf16.get(r.get('cpu_bf16'), '')}), "
            f"torch {r['torch']}, "
            f"{r['threads']} thread(s), {r['rounds']} rounds x {r['seconds']:g} s alternating, updates/s "
            f"(mean [min..max])")
    w = max([4, *(len(c["name"]) for c in r["cases"])])  # the case column fits the longest name
    cols = (f"{'case':<{w}} {'network':<12} {'params':>9} {'batch':>5}  {'DoubleDQN.update':>24}  {'bare torch':>24}  "
            f"{'ratio':>5}  {'cpu ratio':>9}")
    lines = [head, cols, "-" * len(cols)]
    for c in r["cases"]:
        cells = [f"{c[k]['updates_per_s']:.1f} [{c[k]['min']:.1f}..{c[k]['max']:.1f}]" for k in ("learner", "bare")]
        cpu = c.get("learner_over_bare_cpu")
        lines.append(f"{c['name']:<{w}} {c['network']:<12} {c['params']:>9,} {c['batch']:>5}  {cells[0]:>24}  "
                     f"{cells[1]:>24}  {c['learner_over_bare']:>5.2f}  {cpu if cpu is None else format(cpu, '.2f'):>9}")
    lines.append("ratio = DoubleDQN.update / bare torch in updates/s (numpy batch in, as the learner gets it, vs "
                 "resident tensors); cpu ratio = the same in updates per CPU-second of this process")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
