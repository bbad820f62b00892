"""An env worker: runs env copies, acts epsilon-greedily with its latest weights, sends batches.

The worker only knows the three tiny seams of ``seams`` (Acme style: ``ExperienceSink``,
``WeightsSource``, ``RunControl``, as one ``ActorLinks``), so the same class runs inside a Ray
actor over zenoh (``links.ZenohActorLinks``) and in-process in unit tests
(``laneshift.deploy.inprocess``); the links own the encoding, and what crosses is typed:
transitions batches and episode records out, decoded weights in.

Every ``send_every`` env steps it publishes one transitions batch (MATLAB: "workers send their
experience every N steps"). With ``n_step > 1`` the batch holds n-step items (laneshift.nstep),
each sent once its n rewards are known, so a batch can hold up to n - 1 items fewer or more. In
``sync`` mode it then waits for the next weights version, so no step is ever taken with stale
weights; in ``async`` mode it takes the newest version if one came.

A stop (the run's stop message: the launcher's graceful end, SIGTERM or SIGINT) ends the batch
being filled: its items and the n-step items still pending go out as a last, shorter batch, and
the worker flushes (bounded: a couple of seconds after a stop) like one whose budget is spent.
What the replay server has not confirmed then is counted lost in the summary
(``undelivered_batches``, ``undelivered_items``) and said in the worker's log, never silently.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from laneshift import wire
from laneshift.config import ActorConfig, EnvConfig
from laneshift.nstep import NStepAccumulator, NStepItem, check_nstep

from .envs import make as make_env
from .exploration import HeldExploration, make_schedule
from .policy import QPolicy
from .seams import ActorLinks, Delivery, WeightsUpdate


@dataclass
class WorkerSummary:
    name: str
    env_steps: int
    episodes: int
    batches: int
    versions_used: list[int]
    weight_updates: int
    bad_weights: int
    first_weights_sha256: str  # digest of the first weights acted with (rehearsal: the phase-1 network)
    wall_s: float
    rate_limited_s: float = 0.0  # blocked by the replay's rate limiter: the learner bounds the run
    #: Sent, and not confirmed held by the replay server when the final flush ended (a stop, a
    #: server down or too slow to answer): counted lost here; the run's lost count is the server's
    #: record (its gaps, and the launcher's count of the batches after its newest).
    undelivered_batches: int = 0
    undelivered_items: int = 0

    def as_dict(self) -> dict:
        """JSON-ready; ``versions_used`` (one entry per batch sent, 23k for a 750k-step worker)
        becomes ``version_runs``: ``[[version, batches], ...]`` in order (see ``expand_version_runs``)."""
        out = dict(self.__dict__)
        out["version_runs"] = version_runs(out.pop("versions_used"))
        return out


def version_runs(versions: list[int]) -> list[list[int]]:
    """Run-length encode: ``[3, 3, 4] -> [[3, 2], [4, 1]]``."""
    runs: list[list[int]] = []
    for v in versions:
        if runs and runs[-1][0] == v:
            runs[-1][1] += 1
        else:
            runs.append([v, 1])
    return runs


def expand_version_runs(runs: list[list[int]]) -> list[int]:
    """The inverse of ``version_runs``: the weights version of each batch, in order."""
    return [v for v, n in runs for _ in range(n)]


@dataclass(frozen=True)
class Resume:
    """Where a (re)started worker begins: env steps already done, the next batch's seq."""

    env_steps: int = 0
    next_seq: int = 0
    restarts: int = 0


class EnvWorker:
    def __init__(self, name: str, index: int, env_cfg: EnvConfig, actor_cfg: ActorConfig,
                 hidden: tuple[int, ...], sync: bool, rehearsal: bool, n_step: int = 1, gamma: float = 0.99,
                 dueling: bool = False, cnn: str = "nature", heads: int = 1):
        self.name, self.index, self.cfg = name, index, actor_cfg
        self.sync, self.rehearsal = sync, rehearsal
        self.envs = [make_env(env_cfg) for _ in range(actor_cfg.envs_per_worker)]
        self.n_step, self.gamma = n_step, gamma
        check_nstep(n_step, gamma)  # a bad n or gamma is refused here, not mid-run
        space = self.envs[0].observation_space
        self.policy = QPolicy(tuple(space.shape), int(self.envs[0].action_space.n), hidden,
                              seed=actor_cfg.seed + 7919 * index, dueling=dueling, cnn=cnn, heads=heads,
                              torch_threads=actor_cfg.torch_threads)
        self.uses_policy_vehicles = env_cfg.policy_vehicles > 0
        self.bad_weights = 0
        self.weight_updates = 0
        self.first_weights_sha256 = ""

    # ------------------------------------------------------------------ weights

    def _apply(self, update: WeightsUpdate) -> bool:
        if update is None:
            return False
        if isinstance(update, wire.WireError):
            self.bad_weights += 1  # counted and ignored: keep acting with the weights we have
            return False
        if update.version <= self.policy.version:
            return False  # an older or repeated version (e.g. a query answer after an update)
        try:
            self.policy.load(update)
        except ValueError:
            self.bad_weights += 1  # another network's weights: counted and ignored, like a bad message
            return False
        if not self.first_weights_sha256 and (not self.rehearsal or update.phase == 2):
            self.first_weights_sha256 = wire.tensors_digest(update.tensors)
        self.weight_updates += 1
        if self.uses_policy_vehicles:
            for env in self.envs:  # other vehicles driven by a copy of the agent's current model
                env.unwrapped.set_npc_policy(self.policy.greedy)
        return True

    def _await_weights(self, links: ActorLinks, newer_than: int, phase: int | None = None) -> bool:
        """Block until a version > ``newer_than`` (and of ``phase``, if given) is loaded."""
        while not links.stop_requested():
            self._apply(links.wait_weights(0.5))
            if self.policy.version > newer_than and (phase is None or self.policy.phase == phase):
                return True
        return False

    # ------------------------------------------------------------------ acting

    def run(self, links: ActorLinks, env_steps: int, resume: Resume | None = None) -> WorkerSummary:
        """Act until ``env_steps`` steps (over all env copies) are done, then return a summary.

        ``resume``: a restarted worker goes on from what the replay server stored of it: its step
        count (and so its epsilon) and its batch sequence, so the budget is spent once and every
        batch it ever sent is either stored or counted as lost.
        """
        started = time.monotonic()
        resume = resume or Resume()
        # Rehearsal: phase 1 learns from demos alone, so workers start with the phase-2 network.
        if not self._await_weights(links, -1, phase=2 if self.rehearsal else None):
            return self._summary(0, 0, 0, [], started)
        cfg = self.cfg
        if self.rehearsal and cfg.phase2_epsilon_start >= 0:  # workers act only in phase 2
            cfg = dataclasses.replace(cfg, epsilon_start=cfg.phase2_epsilon_start)
        epsilon = make_schedule(cfg, self.index, budget=env_steps)
        n_envs = len(self.envs)
        held = (HeldExploration(n_envs, self.policy.n_actions, cfg.hold_mu, cfg.hold_max, self.policy.rng)
                if cfg.hold_mu > 0 else None)
        # A resumed worker reseeds differently: replaying the first run's episodes would bias the data.
        seed = self.cfg.seed + 1000 * self.index + 7_777_777 * resume.restarts
        obs = np.stack([env.reset(seed=seed + j)[0] for j, env in enumerate(self.envs)])
        ep_return, ep_len = np.zeros(n_envs), np.zeros(n_envs, np.int64)
        episodes = 0
        steps, seq = resume.env_steps, resume.next_seq
        versions: list[int] = []
        iters = max(1, -(-self.cfg.send_every // n_envs))
        pending = [NStepAccumulator(self.n_step, self.gamma) for _ in self.envs]
        items: list[NStepItem] = []
        rate_limited_s = 0.0
        stopping = False
        while steps < env_steps and not stopping:
            if not self.sync:  # sync is paced by the learner's rounds already
                waited = time.monotonic()
                links.wait_insert_ok()
                rate_limited_s += time.monotonic() - waited
            for _ in range(iters):
                if links.stop_requested():
                    stopping = True  # the batch being filled ends here: what it holds is sent below
                    break
                eps = epsilon(steps)
                if held is None:
                    actions = self.policy.act(obs, eps)
                else:
                    actions = held.act(self.policy.greedy(obs), eps)
                # The budget's last step may need fewer than all envs: never overrun it.
                for j, env in enumerate(self.envs[:env_steps - steps]):
                    next_obs, reward, terminated, truncated, info = env.step(int(actions[j]))
                    items += pending[j].push(obs[j].copy(), int(actions[j]), float(reward), next_obs,
                                             bool(terminated), bool(truncated))
                    ep_return[j] += reward
                    ep_len[j] += 1
                    if terminated or truncated:
                        episodes += 1
                        links.send_episode(wire.EpisodeRecord(
                            self.name, float(ep_return[j]), int(ep_len[j]), bool(info.get("crashed", False)),
                            bool(info.get("on_target_lane", False)), self.policy.version, self.policy.phase,
                            env_steps=steps + j + 1, epsilon=float(eps)))
                        ep_return[j], ep_len[j] = 0.0, 0
                        if held is not None:
                            held.end_episode(j)
                        next_obs, _ = env.reset()
                    obs[j] = next_obs
                steps += min(n_envs, env_steps - steps)
                if steps >= env_steps:
                    break
            if steps >= env_steps or stopping:  # the budget's (or the stop's) last items bootstrap from here
                for j, acc in enumerate(pending):
                    items += acc.flush(obs[j].copy())
            if not items:  # n-step: nothing complete yet (fewer than n steps so far)
                continue
            links.send_transitions(self._batch(seq, steps, items))
            items = []
            versions.append(self.policy.version)
            seq += 1
            if stopping:
                break
            if self.sync and steps < env_steps:
                # MATLAB sync: the host learns from every worker's batch, then sends new parameters to all.
                # A stop ends the wait; the next pass sends the n-step items still pending, and ends.
                self._await_weights(links, self.policy.version)
            else:
                self._apply(links.latest_weights())
        # What the server lacks is sent again (after a stop for a couple of seconds only); what it
        # has not confirmed then is counted lost, and said.
        delivery = links.flush()
        if not delivery.complete:
            print(f"{self.name}: {delivery.undelivered_batches} batches ({delivery.undelivered_items} items) sent "
                  f"and not confirmed by the replay server when this worker ended: counted lost (the run's "
                  f"summary counts what the server holds)", flush=True)
        return self._summary(steps, episodes, seq, versions, started, rate_limited_s, delivery)

    def _batch(self, seq: int, steps: int, items: list[NStepItem]) -> wire.TransitionBatch:
        """Batch ``seq`` of ``items``, made with the current weights, ``steps`` env steps done."""
        return wire.TransitionBatch.from_arrays(
            actor=self.name, seq=seq, weights_version=self.policy.version, phase=self.policy.phase,
            env_steps=steps, obs=np.stack([it.obs for it in items]), action=[it.action for it in items],
            reward=[it.reward for it in items], next_obs=np.stack([it.next_obs for it in items]),
            terminated=[it.terminated for it in items], truncated=[it.truncated for it in items],
            steps=[it.steps for it in items])

    def _summary(self, steps: int, episodes: int, batches: int, versions: list[int], started: float,
                 rate_limited_s: float = 0.0, delivery: Delivery | None = None) -> WorkerSummary:
        delivery = delivery or Delivery()
        return WorkerSummary(self.name, steps, episodes, batches, versions, self.weight_updates, self.bad_weights,
                             self.first_weights_sha256, round(time.monotonic() - started, 3), round(rate_limited_s, 3),
                             delivery.undelivered_batches, delivery.undelivered_items)

    def close(self) -> None:
        for env in self.envs:
            env.close()
