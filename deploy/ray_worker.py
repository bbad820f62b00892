"""The env worker as a Ray actor: opens its own zenoh client session inside the worker process."""

from __future__ import annotations

import ray

from laneshift.config import RunConfig, load_run_config


@ray.remote(num_cpus=1, max_restarts=0)
class RayEnvWorker:
    def __init__(self, name: str, index: int, config: dict):
        # Imported here: the Ray worker process builds its own envs and session.
        from laneshift import transport
        from laneshift.actors.links import ZenohActorLinks
        from laneshift.actors.worker import EnvWorker

        cfg: RunConfig = load_run_config(overrides={f"{s}.{k}": v for s, body in config.items() for k, v in body.items()})
        self.session = transport.open_session(cfg.transport)
        self.links = ZenohActorLinks(self.session, cfg.transport.run_id, name, cfg.transport.timeout_s)
        self.worker = EnvWorker(name, index, cfg.env, cfg.actor, cfg.learner.hidden,
                                sync=cfg.train.parallel == "sync", rehearsal=cfg.replay.pretrains,
                                n_step=cfg.learner.n_step, gamma=cfg.learner.gamma, dueling=cfg.learner.dueling)

    def run(self, env_steps: int) -> dict:
        # Which Ray node ran it: on a cluster the run summary shows how the workers were spread.
        return {**self.worker.run(self.links, env_steps).as_dict(), "node": ray.get_runtime_context().get_node_id()}

    def close(self) -> None:
        self.worker.close()
        self.links.close()
        self.session.close()
