"""The run's components as Ray actors: each its own OS process, placed and restarted by Ray.

What it is: thin Ray shells around what ``deploy.builder.Builder`` builds. Every actor has the
same shape, so the launcher supervises them all alike:

- the constructor builds and starts the component (after a crash Ray runs it again, and the
  component restores its own checkpoint: replay table, learner state, the router's endpoint);
- ``run()`` blocks while the component works (an env worker: until its budget is spent) and
  fails with ``RayActorError`` if the process dies, which is how the launcher learns of it;
- ``info()`` says where it runs; ``stop()`` ends it gracefully (threaded actors, so ``stop()``
  runs beside ``run()``).

Each actor writes its output to ``<run dir>/logs/<component>.log`` on its node.
Room: deploy, the wiring. May import: the contract, ``deploy.builder``, Ray; components only through the builder.
"""

from __future__ import annotations

import os
import sys
import threading
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import ray

from laneshift.config import RunConfig, load_run_config

if TYPE_CHECKING:
    from laneshift.envspec import EnvSpec

from .builder import Builder
from .pinning import pin_process


def _config(plain: dict) -> tuple[RunConfig, EnvSpec | None]:
    """The run config from its plain form, and the env spec the launcher computed, if it sent one
    (then this process builds no simulator just to learn the observation's shape)."""
    plain = dict(plain)
    spec = plain.pop("env_spec", None)
    cfg = load_run_config(overrides={f"{s}.{k}": v for s, body in plain.items() for k, v in body.items()})
    if spec is None:  # the router's: its process never imports the env spec, wire or numpy (about 13 MB)
        return cfg, None
    from laneshift.envspec import spec_from_dict

    return cfg, spec_from_dict(spec, cfg.env)


def _log_to_run_dir(cfg: RunConfig, component: str) -> None:
    """Send this process's stdout and stderr (Python's and native code's) to the run's log file."""
    path = Path(cfg.train.run_dir) / "logs" / f"{component}.log"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    except OSError as exc:  # an unwritable run dir: keep Ray's own worker log instead
        print(f"{component}: cannot log to {path}: {exc}", file=sys.stderr, flush=True)
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    sys.stdout = _LogStream(os.fdopen(1, "w", buffering=1, closefd=False))
    sys.stderr = _LogStream(os.fdopen(2, "w", buffering=1, closefd=False))


class _LogStream:
    """A log stream whose writes never raise: on a full disk a component's print() raised
    OSError (ENOSPC) and took the component down; now the line is lost and counted."""

    def __init__(self, stream):
        self._stream, self.failures = stream, 0

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError:
            self.failures += 1
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError:
            self.failures += 1

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _never_hang_at_exit() -> None:
    """End this actor's process at once when its interpreter shuts down, instead of waiting for
    zenoh's callback threads.

    Why: zenoh-python runs a subscriber's Python callback on a thread of its own that is not a
    daemon and ends only when the subscriber or its session closes. When an actor's process ends
    without closing them (its raylet died with a launcher that was killed -9), CPython's shutdown
    joins those threads for ever: a learner actor was found two hours later, orphaned, its main
    thread in ``threading._shutdown``. By then the component has written everything it keeps
    (checkpoints are written by its own loops and at stop), so flushing the log streams and
    ``os._exit`` lose nothing; it is what ``laneshift.tools.cli_services`` does for the service processes.
    ``threading._register_atexit`` runs before that join (there is no public hook that does)."""

    def leave() -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(0)

    threading._register_atexit(leave)  # type: ignore[attr-defined]


def _write_pid(cfg: RunConfig, component: str) -> None:
    """``<run dir>/logs/<component>.pid``: which process to look at (or to kill, in the chaos suite)."""
    try:
        (Path(cfg.train.run_dir) / "logs" / f"{component}.pid").write_text(str(os.getpid()))
    except OSError:
        pass


def _where() -> dict[str, Any]:
    """This actor's node: its id and the address the node registered with Ray (``ray start
    --node-ip-address``), which is what the other nodes can reach."""
    ctx = ray.get_runtime_context()
    node_id = ctx.get_node_id()
    ip = next((n["NodeManagerAddress"] for n in ray.nodes() if n.get("NodeID") == node_id), None)
    with warnings.catch_warnings():  # deprecated in Ray 2.60 without a replacement for this question
        warnings.simplefilter("ignore")
        restarted = bool(ctx.was_current_actor_reconstructed)
    return {"node_id": node_id, "node_ip": ip or ray.util.get_node_ip_address(), "pid": os.getpid(),
            "restarted": restarted}


class _Service:
    """Shared shape of the router, replay-server and learner actors."""

    component = ""

    def _begin(self, plain: dict) -> RunConfig:
        cfg, self.spec = _config(plain)
        _log_to_run_dir(cfg, self.component)
        _write_pid(cfg, self.component)
        _never_hang_at_exit()
        pinned = pin_process(cfg.deploy.learner_core, learner=self.component == "learner")
        if pinned:
            print(f"{self.component}: {pinned}", flush=True)
        self.stop_event = threading.Event()
        self.where = _where()
        if self.where["restarted"]:
            print(f"{self.component}: restarted by Ray (pid {os.getpid()})", flush=True)
        return cfg

    def info(self) -> dict[str, Any]:
        return dict(self.where)

    def run(self) -> str:
        self.stop_event.wait()
        return "stopped"


@ray.remote
class RouterActor(_Service):
    component = "router"

    def __init__(self, plain: dict, port: int, host: str):
        cfg = self._begin(plain)
        # Listen on the address of the node this actor landed on (never the driver's), or on
        # deploy.advertise_host. A restart runs this again with the same port: clients reconnect.
        self.endpoint = f"tcp/{host or self.where['node_ip']}:{port}"
        self.router = Builder(cfg, self.spec).router(self.endpoint).start()

    def info(self) -> dict[str, Any]:
        return {**self.where, "endpoint": self.endpoint}

    def stop(self) -> None:
        self.router.close()
        self.stop_event.set()


@ray.remote
class ReplayServerActor(_Service):
    component = "replay-server"

    def __init__(self, plain: dict, shard: int = 0):
        if shard:  # shard i of a sharded replay logs as replay-server-<i> (Builder.replay_servers)
            self.component = f"replay-server-{shard}"
        cfg = self._begin(plain)
        self.cfg = cfg
        self.server = Builder(cfg, self.spec).replay_server(shard)
        self.started = self.server.start()  # restores its checkpoint after a crash
        self.final: dict | None = None

    def info(self) -> dict[str, Any]:
        port = self.started.get("http_port")
        host = self.cfg.replay.http_host
        shown = self.where["node_ip"] if host in ("0.0.0.0", "::") else host
        return {**self.where, "http_url": f"http://{shown}:{port}" if port else None,
                "restored_items": self.started.get("restored", 0), "shard": self.server.shard}

    def stats(self) -> dict:
        return self.server.core.stats()

    def broadcast_stop(self) -> None:
        """Tell every env worker (and the learner) to end its loop: the run-wide stop message."""
        from laneshift import wire

        self.server.service.session.put(wire.control_key(self.cfg.transport.run_id), wire.encode_json({"cmd": "stop"}))

    def stop(self) -> dict:
        if self.final is None:
            self.final = self.server.stop()
        self.stop_event.set()
        return self.final


@ray.remote
class LearnerActor(_Service):
    component = "learner"

    def __init__(self, plain: dict):
        import torch

        from laneshift import transport
        from laneshift.learner.process import tune_learner_process

        cfg = self._begin(plain)
        torch.set_num_threads(cfg.learner.torch_threads)
        tune_learner_process()
        builder = Builder(cfg, self.spec)
        self.session = transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes, who="learner",
                                              batching=False)  # sample requests: see session_config
        self.learner = builder.learner(builder.learner_links(self.session, self.stop_event), self.stop_event)

    def info(self) -> dict[str, Any]:
        server = self.learner.prometheus
        host = self.learner.lcfg.metrics_host
        shown = self.where["node_ip"] if host in ("0.0.0.0", "::") else host
        return {**self.where, "metrics_url": f"http://{shown}:{server.port}/metrics" if server else None}

    def run(self) -> dict:
        self.learner.run()  # returns on stop(), a stop message, or the stop criterion
        return {**self.status(), "restored_from": self.learner.restored_from,
                "device": str(self.learner.agent.device)}

    def status(self) -> dict:
        return {**self._last_status(), "checkpoint_failures": self.learner.checkpoint_failures,
                "metrics_write_failures": self.learner.metrics_write_failures}

    def _last_status(self) -> dict[str, Any]:
        """The learner's status of its newest log interval as the launcher reads it ({} before the first)."""
        status = self.learner.last_status
        return status.to_dict() if status is not None else {}

    def stop(self) -> None:
        self.stop_event.set()


@ray.remote
class EnvWorkerActor:
    """One env worker; its ``run`` returns the worker's summary when its budget is spent."""

    def __init__(self, plain: dict, index: int):
        from laneshift import transport

        cfg, spec = _config(plain)
        builder = Builder(cfg, spec)
        self.cfg, self.name = cfg, builder.workers[index]
        _log_to_run_dir(cfg, self.name)
        _write_pid(cfg, self.name)
        _never_hang_at_exit()
        pinned = pin_process(cfg.deploy.learner_core, learner=False)
        if pinned:
            print(f"{self.name}: {pinned}", flush=True)
        self.where = _where()
        self.session = transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes,
                                              who=self.name)
        self.links = builder.actor_links(self.session, self.name)
        self.worker = builder.env_worker(index)

    def info(self) -> dict[str, Any]:
        return dict(self.where)

    def run(self, env_steps: int, restarts: int = 0) -> dict:
        from laneshift.actors.worker import Resume

        # Where the replay server says this worker stands (a first start: zeros).
        state = self.links.wait_stored_state(self.cfg.deploy.start_timeout_s, self.cfg.transport.router)
        resume = Resume(env_steps=min(state["env_steps"], env_steps), next_seq=state["next_seq"], restarts=restarts)
        summary = self.worker.run(self.links, env_steps, resume).as_dict()
        return {**summary, "node": self.where["node_id"], "node_ip": self.where["node_ip"], "restarts": restarts,
                "resumed_at": resume.env_steps,
                "resent": self.links.resent}  # batches sent again that the replay server lacked (or may have)
