"""``laneshift train --local``: the whole system on one machine, with the real components.

This is the one place that wires every component; read it as the diagram::

    router (zenoh, tcp/127.0.0.1:<free port>)          <- every process is a client of it
      ^ replay-server process   transitions/* in, replay/sample + replay/stats queryables
      ^ learner process         samples, Double DQN, weights out (+ weights/latest queryable)
      ^ Ray actors w0..wN-1     env copies, epsilon-greedy, transitions every K steps
      ^ this process            live progress (learner/stats), stop command, final summary

Ray state stays in a temp dir (never ``~/.ray`` or ``/tmp/ray``); token auth is disabled for this
loopback-only local cluster. Ctrl-C or any error stops every child: actors, learner, replay
server, router, Ray.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import TextIO

from laneshift import transport, wire
from laneshift.config import RunConfig, save_run_config
from laneshift.learner.loop import worker_budgets, worker_names

from .processes import ChildFailed, ProcessGroup, wait_for_file


def _default_demo_episodes(cfg: RunConfig) -> int:
    """Scripted episodes for the default shard: ``train.demo_episodes``, else enough for
    retention's demo region (or 2,000 transitions for rehearsal), at least 20."""
    from laneshift.envspec import make_env

    if cfg.train.demo_episodes:
        return cfg.train.demo_episodes
    need = cfg.replay.capacity * cfg.replay.demo_ratio if cfg.replay.retains_demos else 2_000
    probe = make_env(cfg.env)
    horizon = getattr(probe.unwrapped, "max_steps", None) or 100
    probe.close()
    return max(20, math.ceil(1.3 * need / horizon))


def default_demo_dir(cfg: RunConfig, episodes: int) -> Path:
    """Where the default scripted shard lives (shared by runs; its size and the driver's version
    are in the name, so a run that needs more demos, or a newer driver's, gets a new shard instead
    of a refusal or stale demos)."""
    from laneshift.actors.envs.demonstrator import ScriptedDriver
    from laneshift.envspec import env_spec

    env = cfg.env
    # The observation's shape is in the name: a layout change makes a new shard, not a refusal.
    shape = "x".join(str(d) for d in env_spec(env).schema.obs_shape)
    name = f"{env.scenario.replace('/', '_')}-{env.observation}{shape}-p{env.reward_preset}-scripted-v{ScriptedDriver.VERSION}-{episodes}ep"
    return Path(cfg.train.run_dir).resolve().parent / "demos" / name


def ensure_demo_shard(cfg: RunConfig, out: TextIO) -> RunConfig:
    """Demo modes without a shard get the scripted demonstrator's, generated once if absent."""
    if cfg.replay.demo_mode == "none" or cfg.replay.demo_paths:
        return cfg
    episodes = _default_demo_episodes(cfg)
    path = default_demo_dir(cfg, episodes)
    if not any(path.glob("**/metadata.json")):
        from laneshift.demos.generate import generate_shard

        print(f"train: generating the default demo shard ({episodes} scripted episodes) in {path}", file=out, flush=True)
        generate_shard(path, env_id_or_scenario=cfg.env.scenario, env_kwargs=cfg.env.env_kwargs(),
                       episodes=episodes, seed=cfg.train.seed + 10_000)
    return cfg.replace(replay=dataclasses.replace(cfg.replay, demo_paths=(str(path),)))


def _ray_init(num_cpus: int, address: str | None = None) -> str | None:
    """Start a private local Ray (temp dir of our own, no auth token under the home directory),
    or connect to a running cluster at ``address`` (its own settings apply)."""
    import ray

    if address is not None:
        ray.init(address=address, log_to_driver=True, configure_logging=False)
        return None

    os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # loopback-only cluster; keeps ~/.ray untouched
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    tmp = tempfile.mkdtemp(prefix="lsray-")  # short: Ray's unix socket paths must stay < 108 chars
    ray.init(num_cpus=num_cpus, include_dashboard=False, _temp_dir=tmp, _node_ip_address="127.0.0.1",
             log_to_driver=True, configure_logging=False)
    return tmp


class Progress:
    """One live status line from the learner's stats messages."""

    def __init__(self, out: TextIO, budget: int):
        self.out, self.budget = out, budget
        self.tty = hasattr(out, "isatty") and out.isatty()
        self.last: dict = {}
        self.started = time.monotonic()

    def on_stats(self, payload: bytes) -> None:
        try:
            self.last = wire.decode_json(payload)
        except wire.WireError:
            pass

    def line(self) -> str:
        s = self.last
        if not s:
            return f"[{time.monotonic() - self.started:6.1f}s] starting ..."
        elapsed = max(time.monotonic() - self.started, 1e-6)
        fmt = lambda v, f: format(v, f) if isinstance(v, (int, float)) else "-"  # noqa: E731
        lag = s.get("version_lag") or {}
        return (f"[{elapsed:6.1f}s] steps {s.get('env_steps', 0):>7,}/{self.budget:,} ({s.get('env_steps', 0) / elapsed:5.0f}/s)"
                f" | ep {s.get('episodes', 0):>5} return {fmt(s.get('return_mean'), '7.2f')}"
                f" crash {fmt(s.get('crash_rate'), '.2f')}"
                f" | upd {s.get('updates', 0):>6,} ({fmt(s.get('updates_per_s'), '.0f')}/s)"
                f" loss {fmt(s.get('loss'), '.4f')} q {fmt(s.get('q_mean'), '.2f')}"
                f" | replay {fmt(s.get('replay_size'), ',')} | v{s.get('version', 0)} phase {s.get('phase', 0)}"
                f" lag {'/'.join(str(lag[k]) for k in sorted(lag)) or '-'}")

    def show(self) -> None:
        if self.tty:
            self.out.write("\r\033[K" + self.line())
        else:
            self.out.write(self.line() + "\n")
        self.out.flush()


def train_local(cfg: RunConfig, out: TextIO = sys.stdout, ray_address: str | None = None,
                advertise_host: str = "127.0.0.1") -> int:
    """Run a whole training. Returns the exit code (0 ok, 1 failed, 130 interrupted).

    Local mode by default. With ``ray_address`` the actors go to that Ray cluster and the router
    listens on ``advertise_host`` (an address of this machine the cluster's nodes can reach);
    router, replay server and learner stay processes on this machine (see ``train_cluster``).
    """
    run_dir = Path(cfg.train.run_dir).resolve()
    run_dir.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/{advertise_host}:{transport.free_tcp_port()}"
    cfg = cfg.replace(transport=dataclasses.replace(cfg.transport, router=endpoint),
                      train=dataclasses.replace(cfg.train, run_dir=str(run_dir)),
                      # Local runs serve the HTTP inspection API on a free loopback port unless told otherwise.
                      replay=cfg.replay if cfg.replay.http_port != -1 or ray_address else
                      dataclasses.replace(cfg.replay, http_port=0))
    group = ProcessGroup(run_dir / "logs")
    ray_tmp: str | None = None
    ray_started = False
    session = None
    rc = 1
    started = time.monotonic()
    try:
        stale = run_dir / "replay_checkpoint"
        if stale.exists():  # a new run starts empty; restore is for a replay server restarted mid-run
            print(f"train: removing the previous run's replay checkpoint {stale}", file=out, flush=True)
            shutil.rmtree(stale)
        cfg = ensure_demo_shard(cfg, out)
        config_path = save_run_config(cfg, run_dir / "config.yaml")
        py = [sys.executable, "-m", "laneshift"]
        group.start("router", [*py, "router", "--listen", endpoint])
        ready = run_dir / "logs" / "replay-server.ready"
        ready.unlink(missing_ok=True)
        group.start("replay-server", [*py, "replay-server", "--config", str(config_path), "--ready-file", str(ready)])
        wait_for_file(ready, 120, group, "replay-server")
        http_port = json.loads(ready.read_text()).get("http_port")
        group.start("learner", [*py, "learner", "--config", str(config_path)])
        session = transport.open_session(cfg.transport)
        progress = Progress(out, cfg.train.env_steps)
        stats_sub = session.declare_subscriber(wire.learner_stats_key(cfg.transport.run_id),
                                               lambda s: progress.on_stats(s.payload.to_bytes()))
        print(f"train: run dir {run_dir}; {cfg.actor.workers} workers on {cfg.env.scenario} "
              f"({cfg.env.observation}), demo mode {cfg.replay.demo_mode}, {cfg.train.parallel}, "
              f"budget {cfg.train.env_steps:,} env steps; zenoh router {endpoint}", file=out, flush=True)
        if http_port:
            print(f"train: replay inspection API http://{cfg.replay.http_host}:{http_port}/stats "
                  f"(or: laneshift replay inspect --router {endpoint} --run-id {cfg.transport.run_id})",
                  file=out, flush=True)

        import ray

        from .ray_worker import RayEnvWorker

        ray_started = True
        ray_tmp = _ray_init(num_cpus=max(cfg.actor.workers, os.cpu_count() or 1), address=ray_address)
        names = worker_names(cfg.actor.workers)
        plain = cfg.to_dict()
        workers = [RayEnvWorker.options(name=f"{cfg.transport.run_id}-{n}").remote(n, i, plain)
                   for i, n in enumerate(names)]
        share = worker_budgets(cfg.train.env_steps, len(names))
        pending = [w.run.remote(s) for w, s in zip(workers, share)]
        done: list = []
        while pending:
            ready_refs, pending = ray.wait(pending, timeout=cfg.train.log_every_s)
            done += ready_refs
            _supervise_replay_server(group, out)
            group.check_alive()
            progress.show()
        summaries = ray.get(done)
        if progress.tty:
            out.write("\n")
        # Actors are done: tell the learner to finish (final checkpoint), then stop the rest.
        session.put(wire.control_key(cfg.transport.run_id), wire.encode_json({"cmd": "stop"}))
        if group.wait("learner", 120) is None:
            raise ChildFailed("learner did not stop within 120 s of the stop command")
        last = progress.last
        result = _summary(cfg, run_dir, summaries, last, time.monotonic() - started, out)
        (run_dir / "summary.json").write_text(json.dumps(result, indent=2))
        stats_sub.undeclare()
        rc = 0
    except KeyboardInterrupt:
        print("\ntrain: interrupted; stopping every process", file=out, flush=True)
        rc = 130
    except ChildFailed as exc:
        print(f"\ntrain: {exc}", file=out, flush=True)
        rc = 1
    finally:
        if ray_started:
            import ray

            ray.shutdown()  # on a cluster this only disconnects; our named actors die with the job
            if ray_tmp is not None:
                shutil.rmtree(ray_tmp, ignore_errors=True)
        if session is not None:
            session.close()
        group.stop_all()
    return rc


REPLAY_RESTARTS = 3


def _supervise_replay_server(group: ProcessGroup, out: TextIO) -> None:
    """A replay server that died is started again: it restores its last checkpoint, and actors
    and learner carry on through the router (what was sent meanwhile counts as lost batches)."""
    proc = group.procs["replay-server"]
    if proc.poll() is None:
        return
    code = proc.returncode
    if group.restart_if_dead("replay-server", REPLAY_RESTARTS):
        print(f"\ntrain: replay server exited with code {code}; restarted it "
              f"({group.restarts['replay-server']}/{REPLAY_RESTARTS}), restoring its checkpoint", file=out, flush=True)


def _summary(cfg: RunConfig, run_dir: Path, summaries: list[dict], last: dict, wall: float, out: TextIO) -> dict:
    steps = sum(s["env_steps"] for s in summaries)
    episodes = sum(s["episodes"] for s in summaries)
    lines = [
        "", "== laneshift run summary ==",
        f"scenario        {cfg.env.scenario} ({cfg.env.observation}), demo mode {cfg.replay.demo_mode}, "
        f"{cfg.train.parallel}, {cfg.actor.workers} workers",
        f"env steps       {steps:,} in {wall:.0f} s ({steps / max(wall, 1e-6):.0f} steps/s overall), {episodes} episodes",
        f"ray nodes       {_placement(summaries)}",
        f"learner         {last.get('updates', 0):,} updates, final weights version {last.get('version', 0)}",
        *([f"stopped early   episode {last['stop_reason']['episode']} returned {last['stop_reason']['return']:.3f}"
           f" >= train.stop_return {cfg.train.stop_return} after {last['stop_reason']['elapsed_s']} s"]
          if last.get("stop_reason") else []),
        f"last 100 eps    return {_fmt(last.get('return_mean'))}, length {_fmt(last.get('length_mean'))}, "
        f"crash rate {_fmt(last.get('crash_rate'))}",
    ]
    final = run_dir / "checkpoints" / "final.safetensors"
    result: dict = {"workers": summaries, "learner": last, "wall_s": round(wall, 1), "env_steps": steps,
                    "episodes": episodes, "eval": None}
    if cfg.train.eval_episodes and final.exists():
        from laneshift.evaluate import evaluate_checkpoint, format_result

        result["eval"] = evaluate_checkpoint(final, cfg.env, episodes=cfg.train.eval_episodes,
                                             seed=cfg.train.seed + 12345)
        lines.append(f"greedy eval     {format_result(result['eval'])}")
    lines += [f"run dir         {run_dir}", f"checkpoint      {final}", f"tensorboard     tensorboard --logdir {run_dir / 'tb'}"]
    print("\n".join(lines), file=out, flush=True)
    return result


def _placement(summaries: list[dict]) -> str:
    """``2 (w0 on 46902eba, w1 on dab69b7e)``: how many Ray nodes ran the workers, and which."""
    nodes = {s.get("node") for s in summaries}
    return f"{len(nodes)} (" + ", ".join(f"{s['name']} on {str(s.get('node'))[:8]}" for s in summaries) + ")"


def _fmt(v: object) -> str:
    return f"{v:.3f}" if isinstance(v, (int, float)) else "-"
