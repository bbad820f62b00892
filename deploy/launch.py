"""``laneshift train``: one launcher for local and cluster mode; read it as the diagram.

    router        (RouterActor, zenoh, on a node offering deploy.router_resources; in local mode
                   a session in this process instead: deploy.router_in)
      ^ replay    (ReplayServerActor: tables, demo shard, checkpoints, HTTP API on its node)
      ^ learner   (LearnerActor: Double DQN on learner.device, weights out, full-state checkpoints)
      ^ w0..wN-1  (EnvWorkerActor: envs, epsilon-greedy, transitions every K steps)
    this process  Ray driver: places the actors, supervises them, shows progress, summarises

Every component is a Ray actor built by ``deploy.builder.Builder`` (a local run's router excepted:
this process hosts it, since a local run's Ray processes die with it anyway), placed with its
resources and restarted by Ray up to ``deploy.max_restarts`` times; this launcher notices a death (the
actor's ``run()`` call fails), says so, and calls ``run()`` again on the restarted actor, which
resumes from its checkpoint (replay table, learner state) or from what the replay server stored
of it (an env worker's steps and sequence numbers). Local mode is a private Ray cluster (state
in a temp dir, no token, loopback only); cluster mode joins a running cluster (``--cluster``,
``RAY_ADDRESS``, ``ray job submit``). SIGTERM and SIGINT end the run gracefully at any moment:
final learner and replay checkpoints, summary, nothing left running.

Its helpers: ``run_dir`` (the run dir's lock, resume/overwrite, the default demo shard),
``ray_connection`` (the private or the running Ray cluster), ``summary`` (the end of the run).

Room: deploy, the wiring. May import: the contract, ``deploy``'s own modules, Ray; components
only through the builder.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from laneshift.config import RunConfig, save_run_config

from .builder import Builder

from .errors import LaunchError
from .pinning import own_cpus, pin_process_tree, resolve_learner_core, restore_own_cpus
from .ray_connection import RayConnection
from .run_dir import RunDirLock, default_demo_dir, ensure_demo_shard, prepare_run_dir  # noqa: F401 - re-exported
from .spec_process import SpecProcess
from .summary import RunEnd, summarise


# ---------------------------------------------------------------------------- signals


class StopSignals:
    """SIGTERM and SIGINT set a flag the launcher polls, from before Ray starts to the end.

    Ray's driver installs its own SIGTERM handler (it aborts the process ~3 s later, cutting any
    cleanup short), so ``install()`` runs again once Ray is connected.
    """

    def __init__(self) -> None:
        self.received: int | None = None

    def install(self) -> "StopSignals":
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)
        return self

    def _on_signal(self, signum: int, _frame: Any) -> None:
        if self.received is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C: stop waiting for the graceful end
        self.received = signum

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received else ""

    @staticmethod
    def restore() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL if sig == signal.SIGTERM else signal.default_int_handler)


# ---------------------------------------------------------------------------- progress


class Progress:
    """One live status line from the learner's status."""

    def __init__(self, out: TextIO, budget: int):
        self.out, self.budget = out, budget
        self.tty = hasattr(out, "isatty") and out.isatty()
        self.last: dict = {}
        self.started = time.monotonic()

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
                f" lag {'/'.join(str(lag[k]) for k in sorted(lag)[:8]) or '-'}")

    def show(self) -> None:
        self.out.write(("\r\033[K" if self.tty else "") + self.line() + ("" if self.tty else "\n"))
        self.out.flush()

    def say(self, text: str) -> None:
        """A message on its own line (not overwritten by the next progress line)."""
        self.out.write(("\n" if self.tty else "") + text + "\n")
        self.out.flush()


# ---------------------------------------------------------------------------- the run


class Run:
    """The run's actors and their supervision (the launcher's state, one per ``train``)."""

    def __init__(self, cfg: RunConfig, local: bool, out: TextIO, signals: StopSignals):
        self.cfg, self.local, self.out, self.signals = cfg, local, out, signals
        self.builder = Builder(cfg)
        self.handles: dict[str, Any] = {}
        self.refs: dict[str, Any] = {}  # component -> its pending run() call
        self.deaths: dict[str, int] = {}
        self.where: dict[str, dict] = {}
        self.summaries: dict[str, dict] = {}
        self.progress = Progress(out, cfg.train.env_steps)
        self.replay_final: dict | None = None
        self.learner_final: dict | None = None
        self.timeline: dict[str, float] = {}  # seconds each start-up stage took
        self.env_spec: dict | None = None  # envspec.spec_to_dict of the run's env, shipped to components
        self.router: Any = None  # the router, when it runs in this process (deploy.router_in)

    # -- start

    def _create(self, component: str, cls: Any, *args: Any) -> Any:
        handle = cls.options(**self.builder.placement(component).ray_options()).remote(*args)
        self.handles[component] = handle
        return handle

    def _await_started(self, components: list[str], then: Callable[[str], None] | None = None) -> None:
        """Wait until each component answers ``info()``: placed, built and serving (or say why not).
        ``then(component)`` runs as each one answers, in the order they answer."""
        import ray

        deadline = time.monotonic() + self.cfg.deploy.start_timeout_s
        pending = {self.handles[c].info.remote(): c for c in components}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=max(0.1, deadline - time.monotonic()))
            if not ready:
                first = next(c for c in components if c in pending.values())
                raise LaunchError(_not_started(first, self.builder.placement(first), self.cfg.deploy.start_timeout_s))
            component = pending.pop(ready[0])
            try:
                self.where[component] = ray.get(ready[0])
            except ray.exceptions.RayActorError as exc:
                raise LaunchError(f"{component} failed to start: {_cause(exc)}") from None
            if then is not None:
                then(component)

    def _router_in_launcher(self) -> bool:
        """``deploy.router_in``: the router's session in this process (local mode), or an actor."""
        where = self.cfg.deploy.router_in
        if where == "launcher" and not self.local:
            raise LaunchError("deploy.router_in=launcher needs a local run (--local): on a cluster the router "
                              "must outlive this driver and be placed by Ray (deploy.router_in=actor or auto)")
        return where == "launcher" or (where == "auto" and self.local)

    def start(self) -> None:
        import ray

        from .actors import EnvWorkerActor, LearnerActor, ReplayServerActor, RouterActor

        cfg = self.cfg
        host = cfg.deploy.advertise_host or ("127.0.0.1" if self.local else "")
        port = self.builder.router_port(self.local)
        began = time.monotonic()
        in_launcher = self._router_in_launcher()
        if not self.local:  # a private local cluster is sized for the run; a shared one may not hold it
            self._check_placement(in_launcher)
        if in_launcher:  # opened below, once the actors are on their way (opening takes ~0.4 s)
            endpoint = f"tcp/{host}:{port}"
        else:
            self._create("router", RouterActor, cfg.to_dict(), port, host)
            if host:  # its endpoint is known before it runs: the rest start with it (clients retry until it listens)
                endpoint = f"tcp/{host}:{port}"
            else:  # it listens on the address of the node it lands on: wait to learn which
                self._await_started(["router"])
                endpoint = self.where["router"]["endpoint"]
        self.timeline["router"] = time.monotonic() - began
        # From here on every component is a client of the router where it landed.
        cfg = self.cfg = cfg.replace(transport=dataclasses.replace(cfg.transport, router=endpoint))
        self.builder = Builder(cfg)
        save_run_config(cfg, Path(cfg.train.run_dir) / "config.yaml")
        plain = {**cfg.to_dict(), "env_spec": self.env_spec}
        # The rest start together (each retries until the ones it needs answer): faster than in turn.
        replay_servers = self.builder.replay_servers
        for shard, name in enumerate(replay_servers):
            self._create(name, ReplayServerActor, plain, shard)
        self._create("learner", LearnerActor, plain)
        worker_plain = plain
        if cfg.deploy.worker_router:  # workers reach the router through a relay or proxy
            worker_plain = cfg.replace(transport=dataclasses.replace(cfg.transport, router=cfg.deploy.worker_router)).to_dict()
        for i, name in enumerate(self.builder.workers):
            self._create(name, EnvWorkerActor, worker_plain, i)
        if in_launcher:
            opened = time.monotonic()
            self.router = self.builder.router(endpoint).start(announce=False)
            self.where["router"] = {"node_id": ray.get_runtime_context().get_node_id(),
                                    "node_ip": ray.util.get_node_ip_address(), "pid": os.getpid(),
                                    "restarted": False, "endpoint": endpoint, "in": "launcher"}
            self.timeline["router"] += time.monotonic() - opened
        # Each component runs as soon as it answers, not once the last one has: the learner's
        # first weights, which every env worker waits for, go out as early as they can.
        shares = dict(zip(self.builder.workers, self.builder.budgets))

        def run(name: str) -> None:
            self.refs[name] = self.handles[name].run.remote(*((shares[name], 0) if name in shares else ()))

        self._await_started([*([] if in_launcher else ["router"]), *replay_servers, "learner", *self.builder.workers],
                            then=run)
        self.timeline["rest"] = time.monotonic() - began - self.timeline["router"]
        if self.local and cfg.deploy.learner_core >= 0:
            # After the start (which uses every CPU for the components' imports): Ray's own
            # processes and this launcher off the learner's CPU; workers Ray starts later inherit it.
            moved = pin_process_tree(cfg.deploy.learner_core, skip={self.where["learner"]["pid"]})
            if moved:
                self._say(f"train: CPU {cfg.deploy.learner_core} is the learner's alone (deploy.learner_core; "
                          f"this launcher and {moved - 1} other processes of Ray's moved off it; -1 turns it off)")
        self._say(f"train: run dir {cfg.train.run_dir}; {cfg.actor.workers} workers on {cfg.env.scenario} "
                  f"({cfg.env.observation}), demo mode {cfg.replay.demo_mode}, {cfg.train.parallel}, "
                  f"budget {cfg.train.env_steps:,} env steps; zenoh router {endpoint}")
        for shard, name in enumerate(replay_servers):
            http = self.where[name].get("http_url")
            if http:
                which = f"shard {shard}/{len(replay_servers)} " if len(replay_servers) > 1 else ""
                self._say(f"train: replay {which}inspection API {http}/stats on node {self.where[name]['node_ip']} "
                          f"(or: laneshift replay inspect --router {endpoint} --run-id {cfg.transport.run_id}"
                          + (f" --shards {len(replay_servers)} --shard {shard})" if len(replay_servers) > 1 else ")"))
        learner = self.where["learner"]
        if learner.get("metrics_url"):
            self._say(f"train: learner metrics (Prometheus) {learner['metrics_url']}")
        replay_where = (f"replay server on {self.where['replay-server']['node_ip']}" if len(replay_servers) == 1
                        else ", ".join(f"{n} on {self.where[n]['node_ip']}" for n in replay_servers))
        router = self.where["router"]
        router_where = f"router {'in this launcher ' if router.get('in') == 'launcher' else ''}on {router['node_ip']}"
        self._say(f"train: {router_where}, {replay_where}, learner on {learner['node_ip']}")

    def _check_placement(self, in_launcher: bool) -> None:
        """Refuse at once, with the numbers, a run the cluster cannot hold (placement_check)."""
        import ray

        from .placement_check import Need, check_placement

        names = [*([] if in_launcher else ["router"]), *self.builder.replay_servers, "learner", *self.builder.workers]
        needs = []
        for name in names:
            p = self.builder.placement(name)
            needs.append(Need(name, {"CPU": p.num_cpus, **({"GPU": p.num_gpus} if p.num_gpus else {}),
                                     **p.resources}))
        nodes = [{k: float(v) for k, v in n.get("Resources", {}).items() if not k.startswith("node:")}
                 for n in ray.nodes() if n.get("Alive")]
        verdict = check_placement(needs, nodes)
        if verdict.refusal:
            raise LaunchError(f"cannot place this run on the cluster: {verdict.refusal}")
        if verdict.warning:
            self._say(f"train: warning: {verdict.warning}")

    # -- supervise

    def supervise(self) -> str:
        """Until every worker is done; returns why it ended: ``done`` or a signal's name. (When the
        learner ends the run itself, train.stop_return, its stop message ends the workers too.)"""
        import ray

        d = self.cfg.deploy
        last_move, last_mark = time.monotonic(), None
        while True:
            if self.signals.received:
                return self.signals.name
            workers_left = [n for n in self.builder.workers if n not in self.summaries]
            if not workers_left:
                self._sweep_services()
                return "done"
            ready, _ = ray.wait(list(self.refs.values()), num_returns=1, timeout=self.cfg.train.log_every_s)
            for ref in ready:
                name = next(n for n, r in self.refs.items() if r == ref)
                self._collect(name, ref)
            status = self._learner_status()
            if status:
                self.progress.last = status
            mark = (self.progress.last.get("env_steps"), self.progress.last.get("updates"), len(self.summaries))
            if mark != last_mark:
                last_mark, last_move = mark, time.monotonic()
            elif time.monotonic() - last_move > d.stall_timeout_s:
                raise LaunchError(f"no progress for {d.stall_timeout_s:.0f} s (no transition stored, no update): "
                                  f"check {Path(self.cfg.train.run_dir) / 'logs'} and that every node reaches the "
                                  f"router {self.cfg.transport.router} (deploy.advertise_host)")
            self.progress.show()

    def _collect(self, name: str, ref: Any) -> None:
        import ray

        try:
            result = ray.get(ref)
        except ray.exceptions.RayActorError as exc:
            self._restart(name, exc)
            return
        except ray.exceptions.RayTaskError as exc:
            raise LaunchError(f"{name} failed: {_cause(exc)}; its log: "
                              f"{Path(self.cfg.train.run_dir) / 'logs' / (name + '.log')}") from None
        del self.refs[name]
        if name in self.builder.workers:
            self.summaries[name] = result
        elif name == "learner":
            self.learner_final = result
        else:
            raise LaunchError(f"{name} stopped unexpectedly")

    def _sweep_services(self) -> None:
        """Before the stop: a service that died in the last moments of the run (its failed run()
        not yet seen by ``ray.wait``) is found by its process id and counted like any other death,
        so the summary never reads "restarts none" after a restart, and the stop talks to a running
        process. Costs one ``info()`` round trip per service."""
        import ray

        for name in [n for n in self.refs if n not in self.builder.workers]:
            ready, _ = ray.wait([self.refs[name]], timeout=0)
            if ready:
                self._collect(name, ready[0])
                continue
            try:
                where = ray.get(self.handles[name].info.remote(), timeout=self.cfg.deploy.start_timeout_s)
            except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError) as exc:
                self._restart(name, exc)
                continue
            if where.get("pid") != self.where.get(name, {}).get("pid"):
                self._restart(name, RuntimeError("a new process"))

    def _restart(self, name: str, exc: Exception) -> None:
        """The actor's run() failed: wait until Ray has it back, count a death if its process is
        new (a passing fault, ``ActorUnavailableError`` with the same process, is not one), and
        call run() again: the new process resumes from its checkpoint or the replay server."""
        import ray

        limit, wait_s = self.cfg.deploy.max_restarts, self.cfg.deploy.start_timeout_s
        deadline = time.monotonic() + wait_s
        while True:
            try:
                where = ray.get(self.handles[name].info.remote(), timeout=max(0.1, deadline - time.monotonic()))
                break
            except ray.exceptions.ActorUnavailableError:  # still restarting
                if time.monotonic() > deadline:
                    raise LaunchError(f"{name} died and did not come back within {wait_s:.0f} s") from None
                time.sleep(0.2)
            except ray.exceptions.GetTimeoutError:
                raise LaunchError(f"{name} died and did not come back within {wait_s:.0f} s ({_cause(exc)})") from None
            except ray.exceptions.RayActorError as again:
                raise LaunchError(f"{name} died and Ray will not restart it (deploy.max_restarts={limit}): "
                                  f"{_cause(again)}") from None
        if where.get("pid") != self.where.get(name, {}).get("pid"):
            deaths = self.deaths[name] = self.deaths.get(name, 0) + 1
            self._say(f"train: {name} died ({type(exc).__name__}); Ray restarted it as pid {where.get('pid')} "
                      f"({deaths}/{limit})")
        self.where[name] = where
        self.refs[name] = self._call_run(name)

    def _call_run(self, name: str) -> Any:
        handle = self.handles[name]
        if name in self.builder.workers:
            share = self.builder.budgets[self.builder.workers.index(name)]
            return handle.run.remote(share, self.deaths.get(name, 0))
        return handle.run.remote()

    def _learner_status(self) -> dict | None:
        import ray

        ref = self.handles["learner"].status.remote()
        ready, _ = ray.wait([ref], timeout=2.0)
        if not ready:
            return None
        try:
            return ray.get(ready[0])
        except ray.exceptions.RayError:
            return None

    # -- stop

    def stop(self, graceful_s: float = 120.0) -> None:
        """Workers, then learner (final checkpoint), then replay server (final checkpoint), then router."""
        import ray

        def wait(refs: list, timeout: float) -> None:
            if refs:
                ray.wait(refs, num_returns=len(refs), timeout=timeout)

        pending_workers = [n for n in self.builder.workers if n in self.refs]
        if pending_workers and "replay-server" in self.handles:
            try:
                ray.get(self.handles["replay-server"].broadcast_stop.remote(), timeout=10)
            except ray.exceptions.RayError:
                pass
            wait([self.refs[n] for n in pending_workers], 30)
            for n in pending_workers:
                try:
                    self.summaries[n] = ray.get(self.refs[n], timeout=0)
                except ray.exceptions.RayError:
                    pass
        if "learner" in self.handles:
            try:
                ray.get(self.handles["learner"].stop.remote(), timeout=10)
                if "learner" in self.refs:
                    self.learner_final = ray.get(self.refs["learner"], timeout=graceful_s)
            except ray.exceptions.RayError as exc:
                self._say(f"train: learner did not stop cleanly: {_cause(exc)}")
        finals = []
        for name in (n for n in self.builder.replay_servers if n in self.handles):
            try:
                finals.append(ray.get(self.handles[name].stop.remote(), timeout=graceful_s))
            except ray.exceptions.RayError as exc:
                self._say(f"train: {name} did not stop cleanly: {_cause(exc)}")
        if finals:  # the run's replay as one (a sharded replay: every shard's counters summed)
            from laneshift.replay_stats import merge_replay_stats

            self.replay_final = merge_replay_stats(finals, all_actors=True)
        if "router" in self.handles:
            try:
                ray.get(self.handles["router"].stop.remote(), timeout=10)
            except ray.exceptions.RayError:
                pass
        self.close_router()

    def close_router(self) -> None:
        """The router session in this process, if it holds one (``deploy.router_in``), last of all."""
        if self.router is not None:
            self.router.close()
            self.router = None

    def kill_all(self) -> None:
        import ray

        for handle in self.handles.values():
            try:
                ray.kill(handle, no_restart=True)
            except Exception:  # noqa: BLE001 - already gone
                pass

    # -- end

    def ended(self) -> RunEnd:
        """What the summary reads of the run, once its components have stopped."""
        return RunEnd(cfg=self.cfg, workers=[self.summaries[n] for n in self.builder.workers if n in self.summaries],
                      learner={**self.progress.last, **(self.learner_final or {})}, replay=self.replay_final or {},
                      where=dict(self.where), restarts=dict(self.deaths))

    def _say(self, text: str) -> None:
        self.progress.say(text)


def _cause(exc: BaseException) -> str:
    text = str(exc).strip()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    for ln in reversed(lines):  # the exception line at the end of a remote traceback
        if not ln.startswith(("File ", "^", "~")):
            return ln[:300]
    return type(exc).__name__


def _not_started(component: str, placement: Any, timeout: float) -> str:
    import ray

    try:
        free = {k: v for k, v in ray.available_resources().items() if not k.startswith("node:")}
    except Exception:  # noqa: BLE001
        free = {}
    need = {"CPU": placement.num_cpus, **({"GPU": placement.num_gpus} if placement.num_gpus else {}),
            **placement.resources}
    return (f"{component} did not start within {timeout:.0f} s: it needs {need} on one node; the cluster has "
            f"{ {k: round(v, 2) for k, v in sorted(free.items())} } free (deploy.{component.split('-')[0]}_resources)")


# ---------------------------------------------------------------------------- entry point


def train(cfg: RunConfig, *, address: str | None = None, out: TextIO = sys.stdout, resume: bool = False,
          overwrite: bool = False) -> int:
    """A whole training run. ``address`` None: a private local Ray cluster; else that cluster's.
    Returns 0 (done), 1 (failed), 130 (SIGINT) or 143 (SIGTERM) after a graceful stop."""
    signals = StopSignals().install()  # from the very start: a SIGTERM before Ray is a clean exit too
    started = time.monotonic()
    run_dir = Path(cfg.train.run_dir).resolve()
    cfg = cfg.replace(train=dataclasses.replace(cfg.train, run_dir=str(run_dir)),
                      # Runs serve the HTTP inspection API on a free loopback port unless told otherwise,
                      # and the learner's Prometheus /metrics too.
                      replay=cfg.replay if cfg.replay.http_port != -1 else dataclasses.replace(cfg.replay, http_port=0),
                      learner=cfg.learner if cfg.learner.metrics_port != -1
                      else dataclasses.replace(cfg.learner, metrics_port=0))
    lock = RunDirLock(run_dir)
    ray_conn = RayConnection(address)
    launcher_cpus = own_cpus()  # Run.start may move this process off the learner's CPU
    run: Run | None = None
    spec_child: SpecProcess | None = None
    rc = 1
    try:
        lock.acquire()
        prepare_run_dir(run_dir, resume, overwrite, out)
        # The env's spec, computed here once while Ray starts (Ray's start is mostly waiting), is
        # shipped to the replay server and the learner, which then build no simulator of their own.
        spec_child = SpecProcess(cfg)
        ray_conn.open(cfg)  # contacted and authenticated before anything starts
        ray_s = time.monotonic() - started
        signals.install()  # replace Ray's SIGTERM handler (it would abort the cleanup after ~3 s)
        if signals.received:
            raise KeyboardInterrupt
        cfg = ensure_demo_shard(cfg, out)
        if signals.received:
            raise KeyboardInterrupt
        cfg = cfg.replace(deploy=dataclasses.replace(  # auto -> a CPU in local mode, off on a cluster
            cfg.deploy, learner_core=resolve_learner_core(cfg.deploy.learner_core, local=address is None)))
        run = Run(cfg, local=address is None, out=out, signals=signals)
        run.env_spec = spec_child.result()
        run.start()
        run._say(f"train: started in {time.monotonic() - started:.1f} s (Ray {ray_s:.1f} s, router "
                 f"{run.timeline['router']:.1f} s, replay server, learner and workers {run.timeline['rest']:.1f} s)")
        why = run.supervise()
        if why != "done":
            run._say(f"train: {why} received; stopping gracefully (checkpoints, summary)")
        run.stop()
        # Their processes end before the summary's greedy eval builds an env here (highway-env,
        # pygame, matplotlib: about 70 MB): the run's peak memory is then its training's.
        run.kill_all()
        if run.progress.tty:
            out.write("\n")
        result = summarise(run.ended(), why, time.monotonic() - started, out)
        try:
            (run_dir / "summary.json").write_text(json.dumps(result, indent=2))
        except OSError as exc:  # a full or read-only run dir: the summary above is all there is
            print(f"train: could not write {run_dir / 'summary.json'}: {exc}", file=out, flush=True)
        rc = {"done": 0, "SIGINT": 130, "SIGTERM": 143}.get(why, 0)
    except LaunchError as exc:
        print(f"\ntrain: {exc}", file=out, flush=True)
        if run is not None:
            run.stop(graceful_s=30)
        rc = 1
    except KeyboardInterrupt:
        print("\ntrain: interrupted; stopping every component", file=out, flush=True)
        if run is not None and signals.received:
            run.stop(graceful_s=30)
        rc = 130 if signals.received != signal.SIGTERM else 143
    finally:
        if spec_child is not None:
            spec_child.close()
        if run is not None:
            run.kill_all()
            run.close_router()
        ray_conn.close()
        lock.release()
        signals.restore()
        restore_own_cpus(launcher_cpus)
    return rc
