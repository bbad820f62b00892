"""The one builder: every component of a training run, made from its ``RunConfig``.

What it is: the single place that knows how to construct the replay server, the learner and
the env workers, and with which Ray options each one is placed. Local mode, cluster mode and
the in-process test mode all build through it and differ only in *where* each component runs
(Sample Factory's serial vs parallel runners, Acme's builder used by both of its runners):

    in-process (deploy.inprocess)   threads of one process, in-memory links
    local / cluster (deploy.launch) one Ray actor each (deploy.actors), zenoh links

Room: deploy. May import: the contract (``laneshift.config``, ``wire``, ``envspec``,
``transport``) and the components it builds (that is its job); nothing imports it but ``deploy``
and the commands that start one component (``laneshift.tools.cli``).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from laneshift.config import RunConfig, worker_budgets, worker_names

if TYPE_CHECKING:  # the router's process builds through here without the spec (wire, numpy)
    import zenoh

    from laneshift.actors.links import ZenohActorLinks
    from laneshift.actors.worker import EnvWorker
    from laneshift.envspec import EnvSpec
    from laneshift.learner.links import ZenohLearnerLinks
    from laneshift.learner.loop import Learner
    from laneshift.learner.periodic_eval import EvaluatePolicy
    from laneshift.learner.seams import LearnerLinks
    from laneshift.replay_server.core import ReplayCore
    from laneshift.replay_server.service import ReplayServer

    from .router import Router


def replay_server_names(shards: int) -> list[str]:
    """``["replay-server"]`` for one shard; ``replay-server``, ``replay-server-1``, ... for more."""
    return ["replay-server", *(f"replay-server-{i}" for i in range(1, shards))]


#: The cluster-mode router port when ``deploy.router_port`` is 0 (zenoh's usual port).
CLUSTER_ROUTER_PORT = 7447


@dataclass(frozen=True)
class Placement:
    """Where one component runs: its Ray actor options."""

    name: str  # the Ray actor's name: <run id>-<component>
    num_cpus: float
    num_gpus: float = 0.0
    resources: dict[str, float] = field(default_factory=dict)
    max_restarts: int = 0
    max_concurrency: int = 1  # > 1: a threaded actor whose stop() runs beside its run()
    spread: bool = False  # Ray's SPREAD strategy: over the nodes that fit it, one after another

    def ray_options(self) -> dict[str, Any]:
        opts: dict[str, Any] = {"name": self.name, "num_cpus": self.num_cpus, "num_gpus": self.num_gpus,
                                "max_restarts": self.max_restarts, "max_task_retries": 0,
                                "max_concurrency": self.max_concurrency}
        if self.resources:
            opts["resources"] = dict(self.resources)
        if self.spread:
            opts["scheduling_strategy"] = "SPREAD"
        return opts


class Builder:
    """Builds the components of one run. Cheap to make: nothing is built until asked for."""

    def __init__(self, cfg: RunConfig, spec: EnvSpec | None = None):
        self.cfg = cfg
        self._spec = spec  # as computed by the launcher and shipped here; None: computed on first use

    @property
    def spec(self) -> EnvSpec:
        """The env's observation and action spec, computed once (by building the env) unless given."""
        if self._spec is None:
            from laneshift.actors.envs import spec_of

            self._spec = spec_of(self.cfg.env)
        return self._spec

    @property
    def workers(self) -> list[str]:
        return worker_names(self.cfg.actor.workers)

    @property
    def budgets(self) -> list[int]:
        return worker_budgets(self.cfg.train.env_steps, self.cfg.actor.workers)

    # ------------------------------------------------------------------ what each component is

    def router(self, listen: str) -> Router:
        from .router import Router

        return Router(listen, self.cfg.max_message_bytes)

    def replay_core(self, shard: int = 0) -> ReplayCore:
        """The replay tables and rules alone (the in-process mode drives it directly)."""
        from laneshift.replay_server.service import build_core

        return build_core(self.cfg, self.spec, shard)

    @property
    def replay_servers(self) -> list[str]:
        """The replay servers' component names: ``replay-server``, then ``replay-server-1`` ... for
        the other shards of a sharded replay (``replay.shards``)."""
        return replay_server_names(self.cfg.replay.shards)

    def replay_stats_file(self, shard: int = 0) -> str:
        """The name, in the run dir, of replay shard ``shard``'s final stats (``replay_stats.json``)."""
        from laneshift.replay_server.service import shard_files

        return shard_files(self.cfg, shard)[1]

    def replay_server(self, shard: int = 0) -> ReplayServer:
        """Core + zenoh service + HTTP API, as one server with start()/stop() (shard ``shard``)."""
        from laneshift.replay_server.service import ReplayServer

        return ReplayServer(self.cfg, self.spec, shard=shard)

    def learner(self, links: LearnerLinks, stop: threading.Event) -> Learner:
        from laneshift.learner.loop import Learner

        return Learner(self.cfg, self.spec, links, stop, self.greedy_evaluation())

    def greedy_evaluation(self) -> EvaluatePolicy | None:
        """The learner's ``EvaluatePolicy`` for ``train.eval_every`` (None when off): the run's env,
        ``train.periodic_eval_episodes`` episodes on validation episode seeds (``train.validation_seed``
        on: the same episodes every time, in every seed's run, apart from the studies' test seeds)."""
        t = self.cfg.train
        if not t.eval_interval:
            return None
        from laneshift.actors.evaluation import GreedyPolicy, evaluate_policy

        env_cfg, episodes, seed = self.cfg.env, t.periodic_eval_episodes, t.validation_seed
        return lambda batch: evaluate_policy(lambda env: GreedyPolicy(batch), env_cfg, episodes, seed=seed)

    def learner_links(self, session: zenoh.Session, stop: threading.Event) -> ZenohLearnerLinks:
        from laneshift.learner.links import ZenohLearnerLinks

        return ZenohLearnerLinks(session, self.cfg, self.spec.schema, stop)

    def env_worker(self, index: int) -> EnvWorker:
        from laneshift.actors.worker import EnvWorker

        cfg = self.cfg
        return EnvWorker(self.workers[index], index, cfg.env, cfg.actor, cfg.learner.hidden,
                         sync=cfg.train.parallel == "sync", rehearsal=cfg.replay.pretrains,
                         n_step=cfg.learner.n_step, gamma=cfg.learner.gamma, dueling=cfg.learner.dueling,
                         cnn=cfg.learner.network_cnn, heads=cfg.learner.heads)

    def actor_links(self, session: zenoh.Session, name: str) -> ZenohActorLinks:
        from laneshift.actors.links import ZenohActorLinks

        return ZenohActorLinks(session, self.cfg.transport.run_id, name, self.cfg.transport.timeout_s,
                               self.cfg.replay.shards)

    # ------------------------------------------------------------------ where each component runs

    def placement(self, component: str) -> Placement:
        """Ray options of ``router``, ``replay-server``, ``learner`` or a worker name (``w3``)."""
        d, run = self.cfg.deploy, self.cfg.transport.run_id
        if component == "router":
            return Placement(f"{run}-router", d.router_cpus, 0.0, d.router_resources, d.max_restarts, 2)
        if component in self.replay_servers:
            # The shards of a sharded replay go to different nodes where they fit (each takes its
            # share of the ingest, the memory and the network).
            return Placement(f"{run}-{component}", d.replay_cpus, 0.0, d.replay_resources, d.max_restarts, 4,
                             spread=len(self.replay_servers) > 1)
        if component == "learner":
            res = dict(d.learner_resources)
            gpus = float(res.pop("GPU", 0.0))  # Ray takes GPUs as num_gpus, not as a custom resource
            return Placement(f"{run}-learner", d.learner_cpus, gpus, res, d.max_restarts, 4)
        if component in self.workers:
            return Placement(f"{run}-{component}", d.worker_cpus, 0.0, d.worker_resources, d.max_restarts, 1)
        raise ValueError(f"unknown component {component!r}")

    def router_port(self, local: bool) -> int:
        if self.cfg.deploy.router_port:
            return self.cfg.deploy.router_port
        if local:
            from laneshift.transport import free_tcp_port

            return free_tcp_port()
        return CLUSTER_ROUTER_PORT
