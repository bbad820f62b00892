"""The fault suite's faults: ``FAULTS`` (what each strikes, when, and the settings its run gets on
top of ``FAST``) and ``FAST``, the small, fast run every fault strikes. ``runs.run_fault`` reads
a row and runs it; ``tests/test_faults.py`` runs some of the same faults as fast tests.

Room: the tools (the fault suite). May import: the standard library.
"""

from __future__ import annotations

import signal

#: A small, fast run with every mechanism on (LKA plant: seconds per thousand steps).
FAST = {"env.scenario": "lka", "actor.workers": 2, "actor.send_every": 50, "actor.epsilon_decay_steps": 1000,
        "learner.hidden": "64,64", "learner.batch_size": 64, "learner.publish_every": 10,
        "learner.checkpoint_every": 100, "learner.checkpoint_every_s": 1.0, "replay.samples_per_insert": 8,
        "replay.spi_tolerance": 1024, "replay.min_size": 200, "train.eval_episodes": 0,
        # A fault strikes once metrics.jsonl shows its step count: the learner logs it every 0.1 s
        # (learner.log_every_s), so on a fast machine (CI: 650 to 4,000 steps within 0.5 s; here 600
        # to 5,650 within one 1 s interval) it still lands mid-run; the launcher polls as often.
        "learner.log_every_s": 0.1, "train.log_every_s": 0.1,
        # No learner CPU of its own (the local default): with it this small run spends its whole
        # budget in about 1.5 s of training, before a fault's precondition (a checkpoint, a state
        # saved after training began) can hold; three fault tests then raced the run's end.
        "deploy.learner_core": -1}


FAULTS: dict[str, dict] = {
    "worker": {"component": "w1"},
    # The kill waits for a learner state saved after training began; on a fast machine the whole
    # budget could be spent before one was (the learner alone on its core makes ~340 updates/s
    # here), so states come 4x as often and the replay ratio holds the workers to the learner.
    "learner": {"component": "learner", "needs": "learner_state",
                "overrides": {"learner.checkpoint_every_s": 0.25, "replay.samples_per_insert": 32}},
    # A local run's router lives in the launcher (deploy.router_in auto): killing it is the launcher's
    # row. This row runs the router as its own actor, as on a cluster, and kills that.
    "router": {"component": "router", "overrides": {"deploy.router_in": "actor"}},
    # The replay server: before any checkpoint (its write-ahead log alone brings the table back),
    # once one exists, in the middle of one (checkpoints back to back: the kill lands while one is
    # being copied), and without the log (what arrived since the last checkpoint is lost, counted).
    "replay": {"component": "replay-server", "overrides": {"replay.checkpoint_every_s": 0}},
    "replay-after-checkpoint": {"component": "replay-server", "needs": "replay_checkpoint",
                                "overrides": {"replay.checkpoint_every_s": 0.5}},
    "replay-during-checkpoint": {"component": "replay-server", "needs": "replay_checkpoint", "while": "checkpointing",
                                 "overrides": {"replay.checkpoint_every_s": 0.02, "replay.capacity": 10_000}},
    "replay-no-wal": {"component": "replay-server", "overrides": {"replay.checkpoint_every_s": 0, "replay.wal": "off"}},
    # The replay server at other points of the budget (a checkpoint every 0.5 s): near the end the
    # workers spend theirs while it is down, and wait until the restarted one holds all they sent.
    **{f"replay-at-{pct}": {"component": "replay-server", "at": pct / 100,
                            "overrides": {"replay.checkpoint_every_s": 0.5}} for pct in (10, 50, 90)},
    # The run dir on a 6 MiB tmpfs that fills up: checkpoints fail (counted, retried), training goes on.
    "disk-full": {"disk_mb": 6, "overrides": {"replay.checkpoint_every_s": 2, "replay.capacity": 60_000}},
    # The run dir read-only from an eighth to half of the budget (at most 10 s): over before the run ends (a bind mount remounted ro: EROFS even for root), then writable again.
    "unwritable": {"read_only_s": 10.0, "overrides": {"replay.checkpoint_every_s": 1}},
    # 5,000 actor names, one one-row batch each, from a foreign client, with a stats query after each
    # 500 (strikes.StatsFlood), at an eighth of the budget: a worker may not have sent its first batch yet.
    "stats-flood": {"flood_actors": 5000},
    # The link between the workers and the router (a proxy in front of it, deploy.worker_router):
    # every connection reset at a quarter, half and three quarters of the budget; a 10 s cut (the
    # proxy holds every byte, no connection closes) at a quarter; a slow, jittery link (50 +- 20 ms
    # per chunk each way) for the whole run, reset at half. The workers' resend must lose nothing.
    "link-reset": {"link": {"resets_at": (0.25, 0.5, 0.75)}},
    "link-cut": {"link": {"hold_at": 0.25, "hold_s": 10.0}},
    "slow-link": {"link": {"latency_s": 0.05, "jitter_s": 0.02, "resets_at": (0.5,)}},
    # The launcher itself: SIGTERM (`ray job stop`, systemd, Kubernetes) or kill -9, then
    # `laneshift train --resume RUN_DIR`, which must spend exactly the rest of the budget.
    "launcher-sigterm": {"launcher_signal": signal.SIGTERM, "overrides": {"replay.checkpoint_every_s": 2}},
    "launcher-kill": {"launcher_signal": signal.SIGKILL, "overrides": {"replay.checkpoint_every_s": 2}},
}
