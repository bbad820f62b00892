"""The method presets: the named sets of learner settings of ``laneshift train --method`` and
``laneshift experiment compare --methods`` (docs/RESULTS.md measures them), each a map of
``section.field`` overrides applied on top of the run's config (the user's ``--set`` values win).

Room: the contract (shared by every process). May import: the standard library and ``.checks``
(``ConfigError``).
"""

from __future__ import annotations

from typing import Any

from .checks import ConfigError

# DQfD (Hester et al. 2018): pre-training on demos (20,000 updates), demos kept in the buffer
# (30 % of 300,000 items, i.e. about 300 scripted episodes), large-margin loss on demo rows,
# 10-step returns. Phase 2 explores from epsilon 0.3: the pre-trained network already drives.
_DQFD: dict[str, Any] = {
    "replay.demo_mode": "dqfd", "learner.margin_loss_weight": 1.0, "learner.n_step": 10,
    "learner.phase1_updates": 20_000, "replay.capacity": 300_000, "replay.demo_ratio": 0.3,
    "actor.phase2_epsilon_start": 0.3}

# The learner of dqfd-bc-anneal without its demo mode: 10-step returns, a dueling head, a 300,000-item
# buffer, the step size falling to a tenth over the budget, an average of the online weights as the
# network handed out, exploration ending at 1 %. The paper's modes on it (the `*-anneal` presets)
# answer the paper's question on a learner that converges (`laneshift experiment paper`).
_ANNEALED_LEARNER: dict[str, Any] = {
    "learner.n_step": 10, "learner.dueling": True, "replay.capacity": 300_000,
    "learner.lr_final": 5e-5, "learner.ema_decay": 0.999, "actor.epsilon_final": 0.01}

# dqfd-bc-alongside-safe (below) behind the safety shield: the recipe the shielded presets share.
_SHIELDED: dict[str, Any] = {**_DQFD, **_ANNEALED_LEARNER, "learner.bc_loss_weight": 1.0,
                             "env.alongside_features": True, "learner.terminal_value": -1000.0, "env.shield": True}

METHODS: dict[str, dict[str, Any]] = {
    "none": {"replay.demo_mode": "none"},
    "retention": {"replay.demo_mode": "retention"},
    "rehearsal": {"replay.demo_mode": "rehearsal"},
    # The paper's three modes as the paper defines them (retention: 10 % of the buffer; rehearsal:
    # exploration restarts at epsilon_start in phase 2), on the annealed learner; rehearsal
    # pre-trains as long as dqfd does (20,000 updates).
    "none-anneal": {**_ANNEALED_LEARNER, "replay.demo_mode": "none"},
    "retention-anneal": {**_ANNEALED_LEARNER, "replay.demo_mode": "retention"},
    "rehearsal-anneal": {**_ANNEALED_LEARNER, "replay.demo_mode": "rehearsal", "learner.phase1_updates": 20_000},
    "dqfd": _DQFD,
    # dqfd plus supervised imitation (cross-entropy on demo rows) and a dueling head: the two
    # changes that made the pre-trained network drive like the demonstrator (docs/results-history.md, round 2).
    "dqfd-bc": {**_DQFD, "learner.bc_loss_weight": 1.0, "learner.dueling": True},
    # dqfd-bc whose last network settles instead of being one draw of the TD noise: the step size
    # falls to a tenth over the budget, the network handed out is an average of the online weights
    # (about the last 1,000 updates) and exploration ends at 1 %. Measured against dqfd-bc on the
    # same seeds: no difference three seeds can see (docs/RESULTS.md, the straight road's ablation).
    "dqfd-bc-anneal": {**_DQFD, **_ANNEALED_LEARNER, "learner.bc_loss_weight": 1.0},
    # dqfd-bc-anneal that sees a car alongside: the vector observation's alongside features
    # (env.alongside_features; 6 floats more). On merge, the plain observation's network steered
    # from the on-ramp into cars beside it (docs/RESULTS.md, merge).
    "dqfd-bc-alongside": {**_DQFD, **_ANNEALED_LEARNER, "learner.bc_loss_weight": 1.0, "env.alongside_features": True},
    # dqfd-bc-anneal for which a crash never pays: after a terminal step the target bootstraps -100,
    # the value of driving on in a non-target lane for ever (learner.terminal_value). Measured: on
    # the straight road 2 points higher on the test episodes and equal on the validation ones; on
    # merge lower on both (docs/RESULTS.md).
    "dqfd-bc-safe": {**_DQFD, "learner.bc_loss_weight": 1.0, "learner.dueling": True,
                     "learner.lr_final": 5e-5, "learner.ema_decay": 0.999, "actor.epsilon_final": 0.01,
                     "learner.terminal_value": -100.0},
    # dqfd-bc-alongside for which a crash costs far more than any wait: after a terminal step the
    # target bootstraps -1,000. Chosen on merge's validation episodes among 0, -100, -300 and -1,000
    # (and gamma 0.995): survival and achievement rose with the cost, from both start settings
    # (docs/RESULTS.md, merge: what a crash costs).
    "dqfd-bc-alongside-safe": {**_DQFD, **_ANNEALED_LEARNER, "learner.bc_loss_weight": 1.0,
                               "env.alongside_features": True, "learner.terminal_value": -1000.0},
    # dqfd-bc-alongside-safe behind a safety shield (env.shield, actors/envs/shield.py): a gap rule on
    # what the observation's lane block sees replaces an action that would carry the car into a lane
    # that is not free, or not brake in time for its leader or the end of the merge ramp. The agent
    # is the network and the shield together; the network alone is `--set env.shield=false` at eval.
    # Chosen on validation episodes: the published networks behind it crashed in 0-4 of 200 episodes
    # per setting on every road (docs/RESULTS.md, "behind a safety shield").
    "dqfd-bc-alongside-safe-shield": _SHIELDED,
    # dqfd-bc-alongside-safe-shield whose imitation losses (the margin and the cross-entropy on demo rows)
    # fade linearly to 0 over phase 2 (learner.imitation_final): the pull towards the driver's actions
    # goes, the demos stay in the replay. 3 seeds each, test episodes: above the scripted driver behind
    # the same shield on the straight road, the curve and the roundabout, level with it with 3 policy
    # vehicles; lower on merge's validation episodes (seed 0), so merge keeps the gaps recipe below
    # (docs/RESULTS.md, "Past the teacher"). The published networks were trained as
    # `--method dqfd-bc-alongside-safe-shield --set learner.imitation_final=0`, the same settings.
    "dqfd-bc-alongside-safe-shield-fade": {**_SHIELDED, "learner.imitation_final": 0.0},
    # dqfd-bc-alongside-safe-shield that sees, on each side, where the nearest gap long enough to
    # merge into is (env.gap_features: 4 floats more, the scripted driver's alignment target). Chosen
    # on merge's validation episodes (seed 0, 200 per setting): 100 / 93.5 and 99.5 / 88.0 against
    # 99.5 / 88.0 and 99.5 / 82.0 without them (docs/RESULTS.md, "gap features").
    "dqfd-bc-alongside-gaps-safe-shield": {**_SHIELDED, "env.gap_features": True},
    # The pixel recipe (the paper's 4 x 100 x 100 grayscale frames, here 8 policy steps apart): SmallCNN on
    # rows 22-78 (the road's band) with DrQ's shift; a pre-training by the imitation losses alone for
    # 120,000 updates (a copy of the driver from frames drove far better than DQfD's pre-training), then
    # Double DQN with every layer but the Q output layer frozen for the whole of the measured 150,000 env
    # steps (linear probing: with every layer trained, the TD loss's lift of the Q-values took the copy's
    # features with it); 32 sampled rows per env step, a smaller step size. Float32 convolutions (bf16 is
    # emulated, 10x slower, on CPUs without bf16 instructions), one torch thread in phase 1 (faster than
    # two in the run). Probe 18 of docs/RESULTS.md ("Pixels"): 3 seeds' final networks past the paper's
    # best pixel row; this is the command line of its runs as one name (tests/test_config.py holds it
    # to the recorded config of seed 2's run).
    "dqfd-bc-pixels": {**_DQFD, **_ANNEALED_LEARNER, "learner.bc_loss_weight": 1.0,
                       "env.observation": "grayscale", "env.frame_interval": 8, "learner.cnn": "small",
                       "learner.batch_size": 32, "learner.cnn_rows": "22:78", "learner.augment": "shift",
                       "learner.cnn_precision": "fp32", "learner.phase1_updates": 120_000, "learner.phase1_td": False,
                       "learner.phase1_threads": 1, "learner.frozen_steps": 150_000,
                       "learner.frozen_layers": "all-but-output", "replay.samples_per_insert": 32.0,
                       "replay.capacity": 200_000, "learner.lr": 1e-4, "learner.lr_final": 1e-5},
    # The LKA plant's recipe (MATLAB's lane-keeping example has no demonstrations): one-step Double
    # DQN with a larger step size, learning from 1,000 items on and 64 samples per inserted item;
    # 20,000 env steps centre the car (docs/RESULTS.md, LKA; `laneshift experiment lka`).
    "matlab-dqn": {"replay.demo_mode": "none", "learner.lr": 1e-3, "replay.min_size": 1000,
                   "replay.samples_per_insert": 64.0},
}


def method_settings(method: str, option: str = "method") -> dict[str, Any]:
    """The named method's config overrides; an unknown name is refused naming ``option``."""
    if method not in METHODS:
        raise ConfigError(f"{option}: unknown {method!r} (known: {', '.join(METHODS)})")
    return METHODS[method]
