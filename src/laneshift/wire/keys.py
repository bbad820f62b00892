"""The zenoh key expressions of a run (``laneshift/<run>/...``), the replay shard namespaces and
which shard an actor sends to.

No numpy here: a process that only routes or names keys needs nothing else of the wire.

Room: the contract (shared by every process). May import: the standard library and
``laneshift.config`` (the name rule); no other module of the wire package.
"""

from __future__ import annotations

import re
import zlib

from ..config import NAME  # the names rule: in config, which reads it without numpy

#: A replay key namespace: the run's id, or ``<run>/shard-<i>`` for one shard of a sharded replay.
_REPLAY_NS = re.compile(r"^[A-Za-z0-9_\-]{1,64}/shard-[0-9]{1,3}$")


def _check_name(kind: str, value: str) -> str:
    if kind == "run" and isinstance(value, str) and _REPLAY_NS.fullmatch(value):
        return value
    if not isinstance(value, str) or not NAME.fullmatch(value):
        raise ValueError(f"{kind} {value!r} must match [A-Za-z0-9_-]{{1,64}}")
    return value


#: Replay shards a run may have (``replay.shards``).
MAX_SHARDS = 64


def replay_namespace(run: str, shard: int, shards: int) -> str:
    """What the replay keys of shard ``shard`` of ``shards`` are built from: the run id itself
    when there is one shard (a single replay server's keys are what they always were), else
    ``<run>/shard-<i>``, so ``sample_key(replay_namespace("r", 1, 2))`` is
    ``laneshift/r/shard-1/replay/sample``. The run-wide keys (weights, episodes, control,
    learner stats) always take the run id."""
    _check_name("run", run)
    if not 1 <= shards <= MAX_SHARDS or not 0 <= shard < shards:
        raise ValueError(f"shard {shard} of {shards}: need 0 <= shard < shards <= {MAX_SHARDS}")
    return run if shards == 1 else f"{run}/shard-{shard}"


_TRAILING_DIGITS = re.compile(r"([0-9]+)$")


def shard_of(actor: str, shards: int) -> int:
    """The replay shard an actor sends to: a stable function of its name alone, so a restarted
    actor finds its state (sequence numbers, env steps) on the same shard. A name ending in a
    number (the builder's ``w0``, ``w1``, ...) goes to that number modulo ``shards``, which spreads
    numbered actors evenly; any other name to its CRC-32 modulo ``shards``."""
    _check_name("actor", actor)
    if shards <= 1:
        return 0
    digits = _TRAILING_DIGITS.search(actor)
    return (int(digits.group(1)) if digits else zlib.crc32(actor.encode())) % shards


def transitions_key(run: str, actor: str) -> str:
    """Where actor ``actor`` publishes its transition batches."""
    return f"laneshift/{_check_name('run', run)}/transitions/{_check_name('actor', actor)}"


def transitions_wildcard(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/transitions/*"


def actor_from_transitions_key(key: str) -> str:
    """The actor name at the end of a transitions key (validated)."""
    return _check_name("actor", str(key).rsplit("/", 1)[-1])


def weights_key(run: str) -> str:
    """Learner publishes every new weights version here (subscribe for updates)."""
    return f"laneshift/{_check_name('run', run)}/weights"


def weights_latest_key(run: str) -> str:
    """Queryable answering with the latest weights (for late joiners and reconnects)."""
    return f"laneshift/{_check_name('run', run)}/weights/latest"


def sample_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/sample"


def replay_stats_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/stats"


def replay_control_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/control"


def replay_info_key(run: str) -> str:
    """Queryable: JSON ``{"wire_version", "obs_shape", "obs_dtype", "n_actions", "run_id", "mode", "http_url"}``,
    what a client needs to build TRANSITIONS for this run (docs/wire.md §7)."""
    return f"laneshift/{_check_name('run', run)}/replay/info"


def priorities_key(run: str) -> str:
    """Learner -> replay server: PRIORITIES messages (prioritized sampling)."""
    return f"laneshift/{_check_name('run', run)}/replay/priorities"


def replay_flow_key(run: str) -> str:
    """Replay server -> actors: ``{"insert_ok": bool}``, whether the learner keeps up (rate limiter)."""
    return f"laneshift/{_check_name('run', run)}/replay/flow"


def episodes_key(run: str, actor: str) -> str:
    return f"laneshift/{_check_name('run', run)}/episodes/{_check_name('actor', actor)}"


def episodes_wildcard(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/episodes/*"


def learner_stats_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/learner/stats"


def control_key(run: str) -> str:
    """Run-wide control broadcast (e.g. ``{"cmd": "stop"}``)."""
    return f"laneshift/{_check_name('run', run)}/control"
