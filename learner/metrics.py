"""Learner metrics: TensorBoard event files plus a JSON-lines log in the run dir."""

from __future__ import annotations

import json
import time
from pathlib import Path

from tensorboardX import SummaryWriter


class MetricsLog:
    def __init__(self, run_dir: str | Path):
        self.dir = Path(run_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.tb = SummaryWriter(str(self.dir / "tb"), flush_secs=5)
        self._jsonl = (self.dir / "metrics.jsonl").open("a", buffering=1)
        self.write_failures = 0

    def scalars(self, step: int, values: dict[str, float], kind: str = "learner") -> None:
        for k, v in values.items():
            if isinstance(v, (int, float)):
                self.tb.add_scalar(f"{kind}/{k}", v, step)
        try:
            self._jsonl.write(json.dumps({"kind": kind, "step": step, "time": time.time(), **values}) + "\n")
        except OSError:  # a full disk: the metrics line is lost (counted), training goes on
            self.write_failures += 1

    def hparams(self, config: dict) -> None:
        self.tb.add_text("config", "```\n" + json.dumps(config, indent=2) + "\n```", 0)

    def close(self) -> None:
        self.tb.close()
        try:
            self._jsonl.close()
        except OSError:
            self.write_failures += 1
