"""The run's actors under the launcher (``Run``, one per ``laneshift train``): each component
created as a Ray actor with its placement (``Builder``), the router in the launcher or as an
actor, every one's ``run()`` called as soon as it answers; then supervised: a component whose
``run()`` fails is waited for while Ray restarts it, its death counted, and ``run()`` called again
(it resumes from its checkpoint or from what the replay server stored of it); the learner's
status shown; a stall refused. At the end: workers, learner, replay server and router stopped in
that order, each with its final checkpoint, and what the summary reads of them (``ended``). Once
Ray's head no longer answers (``_cluster_gone``), nothing is waited for: the actors ended with it.

Room: deploy, the wiring. May import: the contract, ``deploy``'s own modules, Ray; components
only through the builder.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from laneshift.config import RunConfig, save_run_config

from .builder import Builder

from .errors import LaunchError
from .pinning import pin_process_tree
from .progress_line import Progress
from .ray_connection import cluster_answers
from .stop_signals import StopSignals
from .summary import RunEnd


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
        self.replay_finals: dict[str, dict] = {}  # stats file name -> that replay server's final stats
        self.learner_final: dict | None = None
        self.timeline: dict[str, float] = {}  # seconds each start-up stage took
        self.env_spec: dict | None = None  # envspec.spec_to_dict of the run's env, shipped to components
        self.router: Any = None  # the router, when it runs in this process (deploy.router_in)
        self.cluster_gone = False  # Ray's head no longer answers: nothing left to wait for (_cluster_gone)

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
        next_probe, head_silent_since = time.monotonic() + HEAD_PROBE_S, None
        while True:
            if self.signals.received:
                return self.signals.name
            if time.monotonic() >= next_probe:
                # The actors go on talking to each other without the head, so only asking it finds
                # it gone; a GCS restarting (fault tolerance on a cluster) is given HEAD_LOST_S.
                next_probe = time.monotonic() + HEAD_PROBE_S
                if cluster_answers():
                    head_silent_since = None
                elif head_silent_since is None:
                    head_silent_since = time.monotonic()
                elif time.monotonic() - head_silent_since >= HEAD_LOST_S:
                    self.cluster_gone = True
                    raise LaunchError(f"Ray's head has not answered for {HEAD_LOST_S:.0f} s: {CLUSTER_GONE}")
            workers_left = [n for n in self.builder.workers if n not in self.summaries]
            if not workers_left:
                self._sweep_services()
                return "done"
            ready, _ = ray.wait(list(self.refs.values()), num_returns=1, timeout=self.cfg.train.log_every_s)
            if self.signals.received:  # a death seen now is the signal's doing (it reached the actors too)
                return self.signals.name
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

        if self._cluster_gone():
            raise LaunchError(f"{name} died with Ray's head ({_cause(exc)}): {CLUSTER_GONE}")
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

    def _cluster_gone(self) -> bool:
        """Whether Ray's head stopped answering (``cluster_answers``), said once; then no component
        can come back or be stopped, and every wait on one would last until Ray ends this process."""
        if not self.cluster_gone and not cluster_answers():
            self.cluster_gone = True
            self._say(f"train: Ray's head does not answer: {CLUSTER_GONE}")
        return self.cluster_gone

    def stop(self, graceful_s: float = 120.0) -> None:
        """Workers, then learner (final checkpoint), then replay server (final checkpoint), then router.
        Once Ray's head is gone (``_cluster_gone``, asked before each step), the steps left are skipped."""
        import ray

        if self._cluster_gone():
            self.close_router()
            return

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
        if "learner" in self.handles and not self._cluster_gone():
            try:
                ray.get(self.handles["learner"].stop.remote(), timeout=10)
                if "learner" in self.refs:
                    self.learner_final = ray.get(self.refs["learner"], timeout=graceful_s)
            except ray.exceptions.RayError as exc:
                self._say(f"train: learner did not stop cleanly: {_cause(exc)}")
        for shard, name in enumerate(self.builder.replay_servers):
            final = (self._stop_replay_server(name, graceful_s) if name in self.handles and not self._cluster_gone()
                     else None)
            if final is not None:
                self.replay_finals[self.builder.replay_stats_file(shard)] = final
        if "router" in self.handles and not self._cluster_gone():
            try:
                ray.get(self.handles["router"].stop.remote(), timeout=10)
            except ray.exceptions.RayError:
                pass
        self.close_router()

    def _stop_replay_server(self, name: str, graceful_s: float) -> dict | None:
        """Stop one replay server and return its final stats. A server that dies while the run
        stops (a kill in the last moments, after ``_sweep_services`` looked) is waited for as in the
        run: Ray restarts it from its write-ahead log and checkpoint, the death is counted, and the
        new process is stopped instead, so its stats and final checkpoint are not lost with it."""
        import ray

        try:
            return ray.get(self.handles[name].stop.remote(), timeout=graceful_s)
        except ray.exceptions.RayActorError as exc:  # died or restarting: wait for the new process
            try:
                self._restart(name, exc)
            except LaunchError as gone:
                self._say(f"train: {name} did not stop cleanly: {gone}")
                return None
        except ray.exceptions.RayError as exc:
            self._say(f"train: {name} did not stop cleanly: {_cause(exc)}")
            return None
        try:
            return ray.get(self.handles[name].stop.remote(), timeout=graceful_s)
        except ray.exceptions.RayError as exc:
            self._say(f"train: {name} did not stop cleanly: {_cause(exc)}")
            return None

    def close_router(self) -> None:
        """The router session in this process, if it holds one (``deploy.router_in``), last of all."""
        if self.router is not None:
            self.router.close()
            self.router = None

    def kill_all(self) -> None:
        import ray

        if self.cluster_gone:  # the actors ended with the head; ray.kill would wait on it
            return
        for handle in self.handles.values():
            try:
                ray.kill(handle, no_restart=True)
            except Exception:  # noqa: BLE001 - already gone
                pass

    # -- end

    def ended(self) -> RunEnd:
        """What the summary reads of the run, once its components have stopped."""
        return RunEnd(cfg=self.cfg, workers=[self.summaries[n] for n in self.builder.workers if n in self.summaries],
                      learner={**self.progress.last, **(self.learner_final or {})}, replay=self._replay_as_one(),
                      where=dict(self.where), restarts=dict(self.deaths))

    def _replay_as_one(self) -> dict:
        """The replay servers' final stats as one (a sharded replay: every shard's counters summed);
        {} if none gave its stats."""
        if not self.replay_finals:
            return {}
        from laneshift.replay_stats import merge_replay_stats

        return merge_replay_stats(list(self.replay_finals.values()), all_actors=True)

    def _say(self, text: str) -> None:
        self.progress.say(text)


#: How often the supervision asks whether Ray's head still answers, and for how long it may not
#: before the run ends: under the 60 s after which Ray's driver ends itself without its GCS (exit 1,
#: no line of ours), over a GCS restart's few seconds.
HEAD_PROBE_S, HEAD_LOST_S = 5.0, 20.0
#: What a run whose Ray head is gone says, once.
CLUSTER_GONE = ("every component ended with it (a signal to the launcher's whole process group, or the head's "
                "node died); nothing more can be stopped or saved, and the components' last checkpoints in the "
                "run dir stand (`--resume` continues from them)")


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
