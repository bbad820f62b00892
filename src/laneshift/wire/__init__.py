"""The wire contract: every message format and zenoh key expression of laneshift.

The package imports only numpy and the standard library, so any process (or a client written from
``docs/wire.md`` in another language) can speak the protocol. Nothing that arrives over the
network is ever unpickled: messages are a fixed binary envelope, a JSON header and raw
little-endian array bytes, validated field by field on decode.

One module per concern, each importing only those above it in this list (no circle):

- ``errors``: ``WireError``, the one exception, with a stable reason label;
- ``keys``: the zenoh key expressions, replay shard namespaces, ``shard_of`` (no numpy);
- ``envelope``: the binary frame, its limits, ``Kind``, the generic ``encode``/``decode``;
- ``batches``: ``TransitionSchema``, ``TransitionBatch``, ``SampledBatch`` (data only);
- ``fastpath``: the canonical-form fast paths of TRANSITIONS and BATCH;
- ``transitions``: TRANSITIONS (actor -> replay server);
- ``sampling``: SAMPLE_REQUEST, BATCH and PRIORITIES (learner <-> replay server);
- ``weights``: WEIGHTS (learner -> actors) and the safetensors codec;
- ``json_messages``: JSON bodies, episode records and ERROR replies.

Every name is imported from here (``from laneshift.wire import TransitionBatch``); the modules are
the code's layout, not an API.

Example::

    >>> import numpy as np
    >>> schema = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=9)
    >>> batch = TransitionBatch.from_arrays(actor="w0", seq=0, weights_version=0, phase=0,
    ...     env_steps=2, obs=np.zeros((2, 3), np.float32), action=np.array([1, 2]),
    ...     reward=np.zeros(2, np.float32), next_obs=np.ones((2, 3), np.float32),
    ...     terminated=np.array([0, 1]), truncated=np.array([0, 0]))
    >>> decode_transitions(encode_transitions(batch), schema).action.tolist()
    [1, 2]

Room: the contract (shared by every process). May import: its own modules and other contract
modules only, never a component, deploy or a tool.
"""

from __future__ import annotations

from ..config import NAME
from .batches import SampledBatch, TransitionBatch, TransitionSchema
from .envelope import (ALLOWED_DTYPES, MAGIC, MAX_BATCH_ROWS, MAX_COUNTER, MAX_HEADER_BYTES, MAX_MESSAGE_BYTES,
                       WIRE_VERSION, Kind, Message, decode, encode, peek_kind)
from .errors import WireError
from .json_messages import (EpisodeRecord, decode_episode, decode_error, decode_json, encode_episode, encode_error,
                            encode_json)
from .keys import (MAX_SHARDS, actor_from_transitions_key, control_key, episodes_key, episodes_wildcard,
                   learner_stats_key, priorities_key, replay_control_key, replay_flow_key, replay_info_key,
                   replay_namespace, replay_stats_key, sample_key, shard_of, transitions_key, transitions_wildcard,
                   weights_key, weights_latest_key)
from .sampling import (PriorityUpdate, SampleRequest, decode_batch, decode_priorities, decode_sample_request,
                       encode_batch, encode_priorities, encode_sample_request)
from .transitions import decode_transitions, encode_transitions
from .weights import (Weights, decode_weights, encode_weights, safetensors_dumps, safetensors_loads,
                      tensors_digest)

__all__ = [
    "ALLOWED_DTYPES", "MAGIC", "MAX_BATCH_ROWS", "MAX_COUNTER", "MAX_HEADER_BYTES", "MAX_MESSAGE_BYTES", "MAX_SHARDS",
    "NAME", "WIRE_VERSION", "EpisodeRecord", "Kind", "Message", "PriorityUpdate", "SampleRequest", "SampledBatch",
    "TransitionBatch", "TransitionSchema", "Weights", "WireError", "actor_from_transitions_key", "control_key",
    "decode", "decode_batch", "decode_episode", "decode_error", "decode_json", "decode_priorities",
    "decode_sample_request", "decode_transitions", "decode_weights", "encode", "encode_batch", "encode_episode",
    "encode_error", "encode_json", "encode_priorities", "encode_sample_request", "encode_transitions",
    "encode_weights", "episodes_key", "episodes_wildcard", "learner_stats_key", "peek_kind", "priorities_key",
    "replay_control_key", "replay_flow_key", "replay_info_key", "replay_namespace", "replay_stats_key",
    "safetensors_dumps", "safetensors_loads", "sample_key", "shard_of", "tensors_digest", "transitions_key",
    "transitions_wildcard", "weights_key", "weights_latest_key",
]
