"""The replay core's sampling (``Sampling``, a base of ``core.ReplayCore``): a SAMPLE request
answered with a batch drawn by the selector (or an ERROR saying why not: rate limited, not ready,
too large), gathered from the demo and online tables; priority updates; and the bytes-in,
bytes-out handlers the zenoh queryable and subscriber call.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from laneshift.wire import (PriorityUpdate, SampledBatch, SampleRequest, WireError, decode_priorities,
                            decode_sample_request, encode_batch, encode_error)


class Sampling:
    """Drawing rows from a core's tables (the state is the core's: ``core.ReplayCore``)."""

    def sample(self, req: SampleRequest) -> SampledBatch | WireError:
        """Draw ``req.num_batches * req.batch_size`` rows, or say why not (rate limited, not ready)."""
        rows = req.batch_size * req.num_batches
        try:
            self.limiter.check_request(rows)
        except ValueError as exc:
            return _retry("request_too_large", str(exc), 0)
        with self.lock:
            if req.min_version >= 0:
                behind = [a for a in req.actors if self.actors.get(a, {}).get("last_version", -1) < req.min_version]
                if behind:
                    self.requests["not_ready"] += 1
                    return _retry("not_ready", f"waiting for {behind} to deliver version {req.min_version}", 2)
            demo_only = self.phase == 1
            if demo_only:
                n_demo, n_online = self.demo.size, 0
            else:
                if not self.limiter.can_sample(size=self.online.size, inserts=self.online.inserted,
                                               samples=self.samples, rows=rows):
                    self.requests["rate_limited"] += 1
                    return _retry("rate_limited", f"online size {self.online.size}, min {self.limiter.min_size}", 5)
                n_demo = self.demo.size if self.cfg.retains_demos else 0
                n_online = self.online.size
            drawn = self.selector.draw(self._rng, rows, n_demo, self.online.tail, n_online, self.online.capacity)
            is_demo = drawn.is_demo
            batch = self._gather(is_demo, drawn.demo_rows, drawn.online_rows, req.num_batches, drawn.weight,
                                 req.next_obs)
            # How many items this draw was over (and, prioritized, their mass and the weights'
            # scale): a learner sampling several shards weighs each by these (learner/shards.py).
            batch.info["live"] = n_demo + n_online
            if self.prioritized:
                batch.info.update(mass=drawn.mass, weight_scale=drawn.scale)
            if not demo_only:
                self.samples += rows
            demo_rows = len(drawn.demo_rows)
            self.sampled_rows += rows
            self.sampled_demo_rows += demo_rows
            self._recent.append((rows, demo_rows))
            self.requests["served"] += 1
            self._rates.add("samples", rows)
        return batch

    def _gather(self, is_demo: np.ndarray, demo_rows: np.ndarray, online_rows: np.ndarray, nb: int,
                weight: np.ndarray, next_obs: bool = True) -> SampledBatch:
        """The drawn rows' columns (``next_obs`` False: all but the next observations)."""
        n = is_demo.shape[0]
        index = np.empty(n, np.int64)
        info = {"phase": self.phase, "prioritized": self.prioritized}
        records = self.online.records
        if demo_rows.shape[0] == 0 and records is not None:
            # All rows online, in a record table: one gather of whole records (storage.record_dtype).
            # The batch's columns are views of it; encode_batch copies each once, into the reply.
            picked = np.take(records, online_rows, mode="clip")
            _take(self.online.key, online_rows, index)
            return SampledBatch(obs=picked["obs"], action=picked["action"], reward=picked["reward"],
                                next_obs=picked["next_obs"] if next_obs else None, terminated=picked["terminated"],
                                steps=picked["steps"],
                                is_demo=is_demo.view(np.uint8), index=index, weight=weight, num_batches=nb, info=info)
        frames = ("obs", "next_obs") if next_obs else ("obs",)
        out = {name: np.empty((n, *self.schema.obs_shape), self.schema.obs_dtype) for name in frames}
        out.update(action=np.empty(n, np.int64), reward=np.empty(n, np.float32), terminated=np.empty(n, np.uint8),
                   steps=np.empty(n, np.uint8))
        if demo_rows.shape[0] == 0:  # all rows online (no demos sampled): gather straight into the outputs
            for name, arr in out.items():
                _take(getattr(self.online, name), online_rows, arr)
            _take(self.online.key, online_rows, index)
        elif online_rows.shape[0] == 0:  # all rows demos (phase 1): the same, from the demo table
            for name, arr in out.items():
                _take(getattr(self.demo, name), demo_rows, arr)
            index[:] = demo_rows
        else:
            d, o = is_demo, ~is_demo
            picked = np.take(records, online_rows, mode="clip") if records is not None else None
            for name in out:
                out[name][d] = getattr(self.demo, name)[demo_rows]
                out[name][o] = picked[name] if picked is not None else getattr(self.online, name)[online_rows]
            index[d] = demo_rows
            index[o] = self.online.key[online_rows]
        return SampledBatch(is_demo=is_demo.astype(np.uint8), index=index, weight=weight, num_batches=nb, info=info,
                            **out)

    def update_priorities(self, update: PriorityUpdate) -> int:
        """New priorities for sampled items (e.g. |TD error|); items evicted since are skipped.

        Returns how many leaves changed. Demo items get ``demo_priority_bonus`` on top (DQfD).
        """
        if not self.prioritized:
            return 0
        cfg = self.cfg
        with self.lock:
            raw = update.priority.astype(np.float64) + cfg.priority_eps
            demo = update.is_demo.astype(bool)
            raw[demo] += cfg.demo_priority_bonus
            demo_live = self.demos_sampled
            ok_demo = demo & (update.index < self.demo.size) & demo_live
            rows = update.index % self.online.capacity
            # Not overwritten (nor dropped with its frames) since sampled.
            ok_online = ~demo & (self.online.key[rows] == update.index) & (update.index >= self.online.tail)
            changed = self.selector.update(update.index[ok_demo], raw[ok_demo], rows[ok_online], raw[ok_online])
            self.priority_updates += 1
            return changed

    def handle_priorities(self, payload: bytes | bytearray | memoryview) -> str | None:
        """Bytes in: apply a PRIORITIES message, or count why it was refused (never raises)."""
        try:
            self.update_priorities(decode_priorities(payload))
        except WireError as exc:
            return self.reject("priorities:" + exc.reason)
        except Exception:  # noqa: BLE001
            return self.reject("priorities:failed")
        return None

    def handle_sample_query(self, payload: bytes | bytearray | memoryview) -> bytes | bytearray:
        """Bytes in, bytes out: what the zenoh queryable replies."""
        # A learner sends the same request bytes every time: decode them once (SampleRequest is frozen).
        last = self._last_request
        if last is not None and payload == last[0]:
            req = last[1]
        else:
            try:
                req = decode_sample_request(payload)
            except WireError as exc:
                self.reject("bad_request:" + exc.reason)
                return encode_error("bad_request", exc.detail)
            self._last_request = (bytes(payload), req)
        result = self.sample(req)
        if isinstance(result, WireError):
            return encode_error(result.reason, result.detail, getattr(result, "retry_after_ms", 0))
        return encode_batch(result)


def _take(column: Any, rows: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = column[rows]`` without the temporary: ``np.take(out=)`` for an array column
    (mode "clip": with the default "raise" numpy buffers ``out``; the rows come from the selector,
    in range by construction); a frame table's stacked view gathers itself."""
    if type(column) is np.ndarray:
        np.take(column, rows, axis=0, out=out, mode="clip")
    else:
        out[...] = column[rows]


def _retry(reason: str, detail: str, retry_ms: int) -> WireError:
    err = WireError(reason, detail)
    err.retry_after_ms = retry_ms  # type: ignore[attr-defined]
    return err
