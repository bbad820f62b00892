"""How many batches the learner asks for in one sample request: ``learner.prefetch``, fewer where
the reply would pass ``MAX_REPLY_BYTES`` (pixel rows, 80 KB each).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np

from laneshift import wire
from laneshift.learner.batches import MAX_REPLY_BYTES, batches_per_request

PIXELS = ((4, 100, 100), "|u1")  # the paper's observation: 40,000 bytes, two per row
VECTOR = ((82,), "<f4")


def test_pixel_requests_stay_under_the_reply_limit_and_vector_ones_keep_prefetch():
    assert batches_per_request(128, 4, *PIXELS) == 3
    assert batches_per_request(32, 4, *PIXELS) == 4
    assert batches_per_request(256, 4, *PIXELS) == 1
    assert batches_per_request(1024, 4, *PIXELS) == 1  # one batch, however large: the request is still made
    assert batches_per_request(256, 4, *VECTOR) == 4
    assert batches_per_request(256, 64, *VECTOR) == 64


def test_the_reply_of_a_capped_request_is_under_the_limit():
    rows = 128 * batches_per_request(128, 4, *PIXELS)
    obs = np.zeros((rows, *PIXELS[0]), np.uint8)
    batch = wire.SampledBatch(obs=obs, next_obs=obs, action=np.zeros(rows, np.int64), reward=np.zeros(rows, np.float32),
                              terminated=np.zeros(rows, np.uint8), steps=np.ones(rows, np.uint8),
                              is_demo=np.zeros(rows, np.uint8), index=np.arange(rows, dtype=np.int64),
                              weight=np.ones(rows, np.float32), num_batches=rows // 128)
    assert len(wire.encode_batch(batch)) <= MAX_REPLY_BYTES < 32 * 2**20
