"""The learner's Prometheus endpoint (``/metrics``), from the status it computes once per log interval.

What it is: a ``prometheus_client`` registry with one collector that turns the learner's latest
status into metrics at scrape time (so a scrape costs the learner nothing between scrapes), plus
the process collector, served by ``prometheus_client``'s own HTTP server on a thread. Counts that
only grow (updates, env steps, episodes) are counters (``_total``); the rest are gauges, with units
in their names. On with ``learner.metrics_port`` (-1 off, 0 a free port); local runs turn it on.
Room: learner (component). May import: prometheus_client, the standard library and ``learner.status``
(no other component).
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Iterator

from prometheus_client import CollectorRegistry, ProcessCollector, start_http_server
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

from .status import LearnerStatus

#: LearnerStatus field -> (metric name, help); counters only grow over a run (resumes included).
COUNTERS = {"updates": ("laneshift_learner_updates_total", "gradient updates made"),
            "env_steps": ("laneshift_learner_env_steps_total", "env steps the run has made (the TensorBoard step)"),
            "episodes": ("laneshift_learner_episodes_total", "episodes the workers reported"),
            "sample_wait_s": ("laneshift_learner_sample_wait_seconds_total",
                              "seconds the update thread waited for a sampled batch (the actors were behind)")}
GAUGES = {"loss": ("laneshift_learner_loss", "TD loss of the newest update"),
          "q_mean": ("laneshift_learner_q_mean", "mean Q of the batch's taken actions, newest update"),
          "td_abs": ("laneshift_learner_td_abs", "mean |TD error| of the newest update"),
          "grad_norm": ("laneshift_learner_grad_norm", "global gradient norm before clipping, newest update"),
          "margin_loss": ("laneshift_learner_margin_loss", "large-margin imitation loss, newest update"),
          "bc_loss": ("laneshift_learner_bc_loss", "cross-entropy imitation loss, newest update"),
          "updates_per_s": ("laneshift_learner_updates_per_second", "updates per second over the last log interval"),
          "sample_wait_share": ("laneshift_learner_sample_wait_ratio",
                                "share of the last log interval the update thread waited for a sampled batch"),
          "version": ("laneshift_learner_weights_version", "newest weights version published"),
          "phase": ("laneshift_learner_phase", "1: demo-only pre-training, 2 or 0: online"),
          "return_mean": ("laneshift_learner_episode_return_mean", "mean return of the last 100 episodes"),
          "length_mean": ("laneshift_learner_episode_length_mean", "mean length of the last 100 episodes"),
          "crash_rate": ("laneshift_learner_crash_ratio", "share of the last 100 episodes that crashed")}


class _StatusCollector:
    def __init__(self) -> None:
        self.status: LearnerStatus | None = None
        self.lock = threading.Lock()

    def collect(self) -> Iterator:
        with self.lock:
            status = self.status
        for key, (name, help_text) in COUNTERS.items():
            if isinstance(value := getattr(status, key, None), (int, float)):
                yield CounterMetricFamily(name.removesuffix("_total"), help_text, value=float(value))
        for key, (name, help_text) in GAUGES.items():
            if isinstance(value := getattr(status, key, None), (int, float)):
                yield GaugeMetricFamily(name, help_text, value=float(value))
        lag = GaugeMetricFamily("laneshift_learner_version_lag", "weights versions each worker's newest episode was behind",
                                labels=["worker"])
        for worker, value in sorted((status.version_lag if status else {}).items())[:64]:  # bounded, whatever the workers
            lag.add_metric([str(worker)], float(value))
        yield lag


class LearnerMetricsServer:
    """``/metrics`` on ``host:port`` (0: a free port, see ``.port``) until ``close()``."""

    def __init__(self, host: str, port: int):
        self.registry = CollectorRegistry()
        self._status = _StatusCollector()
        self.registry.register(self._status)
        ProcessCollector(registry=self.registry)
        self._server, self._thread = start_http_server(port, addr=host, registry=self.registry)
        self.port = int(self._server.server_port)

    def update(self, status: LearnerStatus, env_steps: int) -> None:
        """The newest status; ``env_steps``: the run's env steps as the learner counts them (the
        TensorBoard step), in place of the status's, which is the replay server's count."""
        status = dataclasses.replace(status, env_steps=env_steps)
        with self._status.lock:
            self._status.status = status

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
