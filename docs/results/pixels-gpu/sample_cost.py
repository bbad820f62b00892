"""What drawing pixel rows costs the learner: one replay core with the scripted pixel shard
(60,000 demo items, 4 x 100 x 100 frames), sampled in-process (``deploy.inprocess.InProcessReplay``:
gather, encode, decode) and over zenoh from a ``laneshift replay-server`` process (query round trip,
then decode), for several rows per request. Prints ms per request and per 128 rows.

    python sample_cost.py SHARD_DIR     # the shard run_gpu.py uses (.gpu/runs/demos/straight-grayscale...)
    python sample_cost.py SHARD_DIR no-next-obs   # requests with next_obs=False (phase 1 of the imitation alone)

Room: a study script (docs/results). May import: anything in laneshift.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

from laneshift import transport, wire
from laneshift.config import load_run_config, method_settings, save_run_config
from laneshift.deploy.builder import Builder
from laneshift.deploy.inprocess import InProcessReplay
from laneshift.deploy.processes import ProcessGroup, wait_for_file

SHAPES = [(128, 1), (128, 2), (128, 4), (32, 4)]  # (rows per batch, batches per request)
ROUNDS, WARMUP = 10, 2


def timed(label: str, draw) -> None:
    for rows, nb in SHAPES:
        for _ in range(WARMUP):
            draw(rows, nb)
        start = time.perf_counter()
        size = 0
        for _ in range(ROUNDS):
            size = draw(rows, nb)
        ms = (time.perf_counter() - start) / ROUNDS * 1000
        print(f"{label:9s} {rows:4d} x {nb}  {size / 1e6:5.1f} MB  {ms:6.1f} ms per request  "
              f"{ms / (rows * nb / 128):5.1f} ms per 128 rows", flush=True)


def main() -> int:
    shard = sys.argv[1]
    next_obs = sys.argv[2:] != ["no-next-obs"]
    work = Path(tempfile.mkdtemp(prefix="sample-cost-"))
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    cfg = load_run_config(overrides={**method_settings("dqfd-bc-anneal", "m"), "env.observation": "grayscale",
                                     "replay.capacity": 200_000, "replay.demo_paths": shard, "replay.wal": "off",
                                     "train.run_dir": str(work), "transport.router": endpoint})
    builder = Builder(cfg)
    schema = builder.spec.schema
    core = builder.replay_core(0)
    core.set_phase(1)  # demo rows only: no online items needed
    local = InProcessReplay(core, schema)

    def in_process(rows: int, nb: int) -> int:
        batch = local.sample(wire.SampleRequest(rows, nb, next_obs=next_obs))
        assert (batch.next_obs is not None) == next_obs and len(batch.action) == rows * nb
        # the frames: nearly all of the message
        return batch.obs.nbytes + (batch.next_obs.nbytes if batch.next_obs is not None else 0)

    timed("inprocess", in_process)
    del core, local
    group = ProcessGroup(work / "logs")
    try:
        group.start("replay-server", [sys.executable, "-m", "laneshift", "replay-server", "--config",
                                      str(save_run_config(cfg, work / "config.yaml")), "--embedded-router",
                                      "--ready-file", str(work / "ready")])
        wait_for_file(work / "ready", 300, group, "replay-server")
        with transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes) as session:
            ns = wire.replay_namespace(cfg.transport.run_id, 0, 1)
            transport.query(session, wire.replay_control_key(ns), wire.encode_json({"cmd": "set_phase", "phase": 1}), 5)

            def over_zenoh(rows: int, nb: int) -> int:
                reply = transport.query(session, wire.sample_key(ns),
                                        wire.encode_sample_request(wire.SampleRequest(rows, nb, next_obs=next_obs)), 30)
                batch = wire.decode_batch(reply, schema)
                assert (batch.next_obs is not None) == next_obs and len(batch.action) == rows * nb
                return len(reply)

            timed("zenoh", over_zenoh)
    finally:
        group.stop_all(grace_s=5)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
