"""The end of ``laneshift train``: the summary lines and result (env steps, episodes, the
learner's last status, replay losses, restarts, the final greedy evaluation).

It reads a ``RunEnd`` (what the launcher's ``Run`` knows when its components have stopped), never
the launcher itself: ``deploy.launch`` and ``deploy.supervision`` import this module.

Room: deploy, the wiring. May import: the contract, the env-running side's evaluation and the
learner's metrics log (for the final evaluation's TensorBoard scalars).
"""

from __future__ import annotations

import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from laneshift.checkpoints import run_checkpoint
from laneshift.config import RunConfig


@dataclass(frozen=True)
class RunEnd:
    """A finished run, as the summary reads it (``deploy.supervision.Run.ended``)."""

    cfg: RunConfig
    workers: list[dict]  # each env worker's final summary, in the builder's order (those that returned one)
    learner: dict  # the learner's last status, updated by its final result
    replay: dict  # the replay servers' final stats as one ({} if they gave none)
    where: dict[str, dict]  # component -> its placement (``node_id``, ``node_ip``)
    restarts: dict[str, int]  # component -> how many times it died and was restarted


def summarise(run: RunEnd, why: str, wall: float, out: TextIO) -> dict:
    """Print the summary lines to ``out``; return the run's result (``train``'s, which the
    experiments read). With ``train.eval_episodes`` and a final checkpoint of a run that was not
    cut short it also evaluates that network (greedy episodes in this process): ``eval``."""
    cfg, run_dir = run.cfg, Path(run.cfg.train.run_dir)
    summaries, last, replay = run.workers, run.learner, run.replay
    actors = replay.get("actors", {})
    steps = sum(s["env_steps"] for s in summaries)
    episodes = sum(s["episodes"] for s in summaries)
    # Workers that ended without their summary (Ray's head went with them): the learner's last
    # count of stored env steps is then the better figure, said as such.
    missing = cfg.actor.workers - len(summaries)
    steps_note = ""
    if missing > 0 and int(last.get("env_steps") or 0) > steps:
        steps = int(last["env_steps"])
        steps_note = f" (the learner's last count: {missing} of {cfg.actor.workers} workers ended without a summary)"
    total = replay.get("actors_total") or {}  # every actor, evicted ones included
    lost_batches = int(total.get("lost_batches", sum(int(a.get("lost_batches", 0)) for a in actors.values())))
    lost_items = int(total.get("lost_items", sum(int(a.get("lost_items", 0)) for a in actors.values())))
    # Batches a worker sent after the last one the server saw (it ended while the server was
    # down): no later batch shows their gap, so the worker's own count does.
    for s in summaries:
        seen = actors.get(s["name"], {"last_seq": -1, "env_steps": 0})
        lost_batches += max(0, s["batches"] - 1 - int(seen["last_seq"]))
        lost_items += max(0, s["env_steps"] - int(seen["env_steps"]))
    waits = wait_shares(summaries, last)
    failures = write_failures(replay, last)
    placement = {**{k: {"node_id": v["node_id"], "node_ip": v["node_ip"]} for k, v in run.where.items()},
                 **{s["name"]: {"node_id": s.get("node"), "node_ip": s.get("node_ip")} for s in summaries}}
    nodes = sorted({p["node_ip"] for p in placement.values() if p.get("node_ip")})
    lines = [
        "", "== laneshift run summary ==",
        f"scenario        {cfg.env.scenario} ({cfg.env.observation}), demo mode {cfg.replay.demo_mode}, "
        f"{cfg.train.parallel}, {cfg.actor.workers} workers" + (f"; ended by {why}" if why != "done" else ""),
        f"env steps       {steps:,} in {wall:.0f} s ({steps / max(wall, 1e-6):.0f} steps/s overall), "
        f"{episodes} episodes{steps_note}",
        f"ray nodes       {len(nodes)} ({', '.join(nodes)}): " + ", ".join(
            f"{k} on {v.get('node_ip')}" for k, v in placement.items()),
        f"replay          {replay.get('tables', {}).get('online', {}).get('inserted', '-')} items stored, "
        f"{lost_batches} batches ({lost_items} items) lost and counted",
        f"restarts        " + (", ".join(f"{k} {v}" for k, v in run.restarts.items()) or "none"),
        *([f"write failures  " + ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in failures.items() if n)
           + " (a full or read-only run dir; each counted, what was not written is said above)"]
          if any(failures.values()) else []),
        f"learner         {last.get('updates', 0):,} updates, final weights version {last.get('version', 0)}"
        + _updates_lost_text(last.get("restored_from")),
        *waits_line(cfg, waits),
        *([f"stopped early   episode {last['stop_reason']['episode']} returned {last['stop_reason']['return']:.3f}"
           f" >= train.stop_return {cfg.train.stop_return} after {last['stop_reason']['elapsed_s']} s"]
          if last.get("stop_reason") else []),
        f"last 100 eps    return {_fmt(last.get('return_mean'))}, length {_fmt(last.get('length_mean'))}, "
        f"crash rate {_fmt(last.get('crash_rate'))}",
    ]
    final = run_checkpoint(run_dir)
    # A run cut short before its final checkpoint (Ray's head gone with it) shows the last one it wrote.
    latest = run_checkpoint(run_dir, "latest")
    shown = latest if not final.exists() and latest.exists() else final
    result: dict = {"workers": summaries, "learner": last, "wall_s": round(wall, 1), "env_steps": steps,
                    "episodes": episodes, "eval": None, "ended_by": why, "placement": placement,
                    "restarts": dict(run.restarts), "waits": waits, "write_failures": failures,
                    "replay": {"inserted": replay.get("tables", {}).get("online", {}).get("inserted"),
                               "lost_batches": lost_batches, "lost_items": lost_items,
                               "rejected": replay.get("rejected")}}
    if cfg.train.eval_episodes and final.exists() and why in ("done", "stopped"):
        # Imported here, once the training processes have ended: gymnasium and the env's modules
        # are loaded only for a run that evaluates.
        from laneshift.actors.evaluation import evaluate_checkpoint, format_result

        result["eval"] = evaluate_checkpoint(final, cfg.env, episodes=cfg.train.eval_episodes,
                                             seed=cfg.train.seed + 12345)
        lines.append(f"greedy eval     {format_result(result['eval'])}")
        record_final_eval(run_dir, steps, result["eval"])
    lines += [f"run dir         {run_dir}", f"checkpoint      {shown}",
              f"tensorboard     {_tensorboard_command()} --logdir {run_dir / 'tb'}"]
    print("\n".join(lines), file=out, flush=True)
    return result


def write_failures(replay: dict, learner: dict) -> dict[str, int]:
    """Writes to the run dir that failed and were counted, by kind: the replay server's
    checkpoints and write-ahead-log records, the learner's checkpoints and its metrics records."""
    return {"replay_checkpoints": int((replay.get("checkpoint") or {}).get("failures", 0)),
            "write_ahead_log_records": int((replay.get("wal") or {}).get("failures", 0)),
            "learner_checkpoints": int(learner.get("checkpoint_failures", 0)),
            "metrics_records": int(learner.get("metrics_write_failures", 0))}


#: The final greedy evaluation's numbers that go to TensorBoard (``final_eval/*``) and metrics.jsonl.
FINAL_EVAL_KEYS = ("survival_rate", "achievement_rate", "return_mean", "length_mean")


def record_final_eval(run_dir: Path, env_steps: int, evaluation: dict) -> None:
    """The summary's greedy evaluation beside the run's other metrics: TensorBoard scalars
    ``final_eval/<key>`` at the run's env steps and a metrics.jsonl record of kind ``final_eval``
    (the learner has ended; this appends a new event file to ``<run dir>/tb``)."""
    from laneshift.learner.metrics import MetricsLog

    log = MetricsLog(run_dir)
    try:
        log.write("final_eval", env_steps, {"env_steps": env_steps, "episodes": evaluation.get("episodes"),
                                            **{k: evaluation.get(k) for k in FINAL_EVAL_KEYS}},
                  scalars={f"final_eval/{k}": evaluation.get(k) for k in FINAL_EVAL_KEYS})
    finally:
        log.close()


def _updates_lost_text(restored_from: dict | None) -> str:
    """What a learner restart cost, for the learner's line: the updates it had published and could
    not restore (all of them when it died before its first state save)."""
    lost = int((restored_from or {}).get("updates_lost") or 0)
    if not lost:
        return ""
    how = "without a state checkpoint" if restored_from.get("path") is None else "from its last state checkpoint"
    return f" (restarted {how}: {lost:,} updates lost)"


def wait_shares(summaries: list[dict], last: dict) -> dict[str, float]:
    """Which side bounded the run: the workers' share of their time blocked by the replay's rate
    limiter (the learner was behind the ratio), and the learner's share, from its first batch on,
    waiting for a sampled batch (the workers or the replay were behind; before the first batch it
    waits for the replay to fill, by design). In the run's result as ``waits`` (``bench run`` reads
    it there); empty before the learner reported."""
    if not summaries or not last.get("elapsed_s"):
        return {}
    workers = sum(s.get("rate_limited_s", 0.0) for s in summaries) / max(sum(s["wall_s"] for s in summaries), 1e-6)
    if last.get("training_s"):
        learner = float(last.get("training_wait_s") or 0.0) / max(float(last["training_s"]), 1e-6)
    else:  # a learner that never trained (or an older status): its whole life
        learner = float(last.get("sample_wait_s") or 0.0) / max(float(last["elapsed_s"]), 1e-6)
    return {"workers_rate_limited_share": round(workers, 3), "learner_sample_wait_share": round(learner, 3)}


def waits_line(cfg: RunConfig, shares: dict[str, float]) -> list[str]:
    """The summary's line for ``wait_shares``. Async mode only: sync rounds wait by design."""
    if cfg.train.parallel != "async" or not shares:
        return []
    workers, learner = shares["workers_rate_limited_share"], shares["learner_sample_wait_share"]
    which = ("the learner bounded the run" if workers > learner + 0.05
             else "the workers bounded the run" if learner > workers + 0.05 else "the two were about even")
    return [f"waits           workers {workers:.0%} of their time on the rate limiter, learner {learner:.0%} "
            f"waiting for samples: {which}"]


def _tensorboard_command() -> str:
    """``tensorboard`` as the user can run it: the one beside this Python (a venv not activated)."""
    beside = Path(sys.executable).parent / "tensorboard"
    return str(beside) if beside.exists() and not shutil.which("tensorboard") else "tensorboard"


def _fmt(v: object) -> str:
    return f"{v:.3f}" if isinstance(v, (int, float)) else "-"
