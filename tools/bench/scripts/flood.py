"""A measurement, not a test: 4 messages of 256 MiB sent to a replay server's transitions key
through a router; prints both processes' peak RSS. zenoh's own max message size (set from the
run's config, `transport.max_message_mb`) should drop them before they are buffered whole.

    .venv/bin/python tools/bench/scripts/flood.py 0       # the run's default limit (16 MiB here)
    .venv/bin/python tools/bench/scripts/flood.py 1100    # a limit above the messages: what it was before

Room: the tools (benchmarks: a script run by path from a checkout). May import: anything in laneshift,
zenoh and the standard library.
"""
import json, os, subprocess, sys, time, resource
import zenoh
from laneshift import transport
from laneshift.config import load_run_config, save_run_config
limit_mb = float(sys.argv[1])
port = transport.free_tcp_port(); ep = f"tcp/127.0.0.1:{port}"
run = f"/tmp/flood-{int(limit_mb)}"; os.makedirs(run, exist_ok=True)
cfg = load_run_config(overrides={"env.scenario": "lka", "transport.router": ep, "train.run_dir": run, "transport.max_message_mb": limit_mb})
save_run_config(cfg, f"{run}/config.yaml")
py = sys.executable
router = subprocess.Popen([py, "-c", f"from laneshift.deploy.router import Router; import time; r = Router('{ep}', {cfg.max_message_bytes}).start(); time.sleep(600)"])
replay = subprocess.Popen([py, "-m", "laneshift", "replay-server", "--config", f"{run}/config.yaml", "--ready-file", f"{run}/ready"], stdout=open(f"{run}/replay.log", "w"), stderr=subprocess.STDOUT)
for _ in range(600):
    if os.path.exists(f"{run}/ready"): break
    time.sleep(0.1)
print("ready", os.path.exists(f"{run}/ready"), file=sys.stderr, flush=True)
def peak(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmHWM"): return int(line.split()[1]) // 1024
s = zenoh.open(transport.session_config(ep, "client", 2**31 - 1))
pub = transport.data_publisher(s, "laneshift/run/transitions/evil"); transport.wait_matching(pub, 10)
blob = b"\0" * (256 << 20)
for i in range(4):
    pub.put(blob); print("sent", i, file=sys.stderr, flush=True)
time.sleep(8)
print(json.dumps({"limit_mb": limit_mb, "router_peak_mb": peak(router.pid), "replay_peak_mb": peak(replay.pid)}))
s.close()
# The replay server first, while its router still runs (its graceful stop closes zenoh sessions,
# which waited forever once the router was gone and left it behind), then the router.
replay.terminate()
try:
    replay.wait(20)
except subprocess.TimeoutExpired:
    replay.kill()
    replay.wait()
router.kill()
router.wait()
