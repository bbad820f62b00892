"""A TCP proxy that makes a link slow, jittery, reset or cut: between a run's workers and its
zenoh router (``deploy.worker_router``), for ``laneshift chaos``'s link rows and the network tests.

``LinkProxy(upstream_port)`` listens on 127.0.0.1 and forwards to one upstream (the router): every
chunk read in either direction is delivered ``latency_s`` +- ``jitter_s`` later (uniform), in
order (a TCP stream cannot be reordered, so a chunk never overtakes the one before it); every
``reset_every_s`` (counted from the first client's connection; 0: never), or on ``reset_one()``,
the oldest client connection is closed abruptly (SO_LINGER 0: an RST to both the client and the
upstream), so clients take turns; ``hold(seconds)`` is a cut: nothing is read or delivered either
way, yet no connection closes. Threads, bounded queues, every wait bounded; ``stop()`` closes
everything it opened.

Room: deploy, the wiring. May import: the standard library only.
"""

from __future__ import annotations

import contextlib
import queue
import random
import socket
import struct
import threading
import time
from dataclasses import dataclass, field

CHUNK = 65536



@dataclass
class ProxyStats:
    connections: int = 0
    resets: int = 0
    bytes_up: int = 0  # client -> upstream
    bytes_down: int = 0  # upstream -> client
    chunks: int = 0
    max_queue: int = 0
    delays_s: list[float] = field(default_factory=list)  # a sample of the delays applied

    def as_dict(self) -> dict:
        d = dict(self.__dict__)
        delays = d.pop("delays_s")
        d["delay_ms_min_mean_max"] = ((round(min(delays) * 1e3, 1), round(sum(delays) / len(delays) * 1e3, 1),
                                       round(max(delays) * 1e3, 1)) if delays else None)
        return d


class _Conn:
    """One proxied connection: two sockets, two directions, each a reader and a writer thread."""

    def __init__(self, proxy: "LinkProxy", client: socket.socket, upstream: socket.socket, n: int):
        self.proxy, self.client, self.upstream, self.n = proxy, client, upstream, n
        self.dead = threading.Event()
        self.threads: list[threading.Thread] = []
        self.opened = time.monotonic()
        for sock in (client, upstream):
            sock.settimeout(0.2)  # so every thread notices `dead` within 0.2 s
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for src, dst, up in ((client, upstream, True), (upstream, client, False)):
            q: queue.Queue = queue.Queue(maxsize=512)  # bounded: a slow side back-pressures the reader
            self.threads.append(threading.Thread(target=self._read, args=(src, q, up), daemon=True,
                                                 name=f"proxy{n}-{'up' if up else 'down'}-read"))
            self.threads.append(threading.Thread(target=self._write, args=(dst, q, up), daemon=True,
                                                 name=f"proxy{n}-{'up' if up else 'down'}-write"))
        for t in self.threads:
            t.start()

    def _read(self, src: socket.socket, q: queue.Queue, up: bool) -> None:
        p = self.proxy
        last = 0.0
        while not self.dead.is_set() and not p.stopping.is_set():
            if time.monotonic() < p.held_until:  # held: read nothing, so the sender's buffers fill
                time.sleep(0.05)
                continue
            try:
                data = src.recv(CHUNK)
            except socket.timeout:
                continue
            except OSError:
                break
            if not data:
                break
            delay = max(0.0, p.latency_s + p.rng.uniform(-p.jitter_s, p.jitter_s))
            deliver_at = max(last, time.monotonic() + delay)  # in order: never before the previous chunk
            last = deliver_at
            with p.lock:
                p.stats.chunks += 1
                if up:
                    p.stats.bytes_up += len(data)
                else:
                    p.stats.bytes_down += len(data)
                if len(p.stats.delays_s) < 5000:
                    p.stats.delays_s.append(delay)
                p.stats.max_queue = max(p.stats.max_queue, q.qsize() + 1)
            while not self.dead.is_set() and not p.stopping.is_set():
                try:
                    q.put((deliver_at, data), timeout=0.2)
                    break
                except queue.Full:
                    continue
        self._put_eof(q)

    def _put_eof(self, q: queue.Queue) -> None:
        for _ in range(25):  # at most ~5 s; the writer ends on `dead` anyway
            try:
                q.put((0.0, b""), timeout=0.2)
                return
            except queue.Full:
                if self.dead.is_set():
                    return

    def _write(self, dst: socket.socket, q: queue.Queue, up: bool) -> None:
        p = self.proxy
        while not self.dead.is_set() and not p.stopping.is_set():
            try:
                deliver_at, data = q.get(timeout=0.2)
            except queue.Empty:
                continue
            if not data:  # the other side closed: pass the FIN on, then end the whole connection
                with contextlib.suppress(OSError):
                    dst.shutdown(socket.SHUT_WR)
                break
            wait = deliver_at - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            for _ in range(int(p.max_hold_s / 0.05) + 1):  # a held link: nothing moves, nothing closes
                if time.monotonic() >= p.held_until or self.dead.is_set() or p.stopping.is_set():
                    break
                time.sleep(0.05)
            try:
                dst.sendall(data)
            except socket.timeout:
                # sendall with a timeout may have sent part: the stream is broken, end it.
                break
            except OSError:
                break
        self.close(abrupt=False)

    def close(self, abrupt: bool) -> None:
        if self.dead.is_set():
            return
        self.dead.set()
        for sock in (self.client, self.upstream):
            if abrupt:  # RST instead of FIN
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            with contextlib.suppress(OSError):
                sock.close()

    def join(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        for t in self.threads:
            t.join(max(0.0, deadline - time.monotonic()))


class LinkProxy:
    """``127.0.0.1:<port>`` -> ``upstream``, ``latency_s`` +- ``jitter_s`` per chunk each way,
    one client connection reset every ``reset_every_s`` (0: never). Use as a context manager."""

    def __init__(self, upstream_port: int, *, latency_s: float = 0.05, jitter_s: float = 0.02,
                 reset_every_s: float = 15.0, seed: int = 0, port: int = 0, upstream_host: str = "127.0.0.1"):
        if jitter_s > latency_s:
            raise ValueError("jitter_s must not exceed latency_s")
        self.upstream = (upstream_host, upstream_port)
        self.latency_s, self.jitter_s, self.reset_every_s = latency_s, jitter_s, reset_every_s
        self.rng = random.Random(seed)
        self.lock = threading.Lock()
        self.stopping = threading.Event()
        self.stats = ProxyStats()
        self.reset_log: list[tuple[float, int]] = []  # (wall time, connection number)
        self.held_until = 0.0  # monotonic; see hold()
        self.max_hold_s = 120.0
        self.conns: list[_Conn] = []
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind(("127.0.0.1", port))
        self._listener.listen(64)
        self._listener.settimeout(0.2)
        self.port = self._listener.getsockname()[1]
        self._threads: list[threading.Thread] = []

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.port}"

    def start(self) -> "LinkProxy":
        for target, name in ((self._accept_loop, "proxy-accept"), (self._reset_loop, "proxy-reset")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def __enter__(self) -> "LinkProxy":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _accept_loop(self) -> None:
        n = 0
        while not self.stopping.is_set():
            try:
                client, _ = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            try:
                upstream = socket.create_connection(self.upstream, timeout=5)
            except OSError:
                # The router is not there (yet, or restarting): refuse like it would.
                with contextlib.suppress(OSError):
                    client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                    client.close()
                continue
            n += 1
            conn = _Conn(self, client, upstream, n)
            with self.lock:
                self.stats.connections += 1
                self.conns = [c for c in self.conns if not c.dead.is_set()] + [conn]

    def _reset_loop(self) -> None:
        if self.reset_every_s <= 0:
            return
        # The clock starts when the first client connects (the workers connect once the run's
        # services are up), so the resets fall into the training, not into Ray's start-up.
        for _ in range(6000):  # at most 10 minutes
            if self.stopping.wait(0.1) or self.stats.connections:
                break
        while not self.stopping.wait(self.reset_every_s):
            self.reset_one()

    def live(self) -> list[_Conn]:
        with self.lock:
            return [c for c in self.conns if not c.dead.is_set()]

    def reset_one(self) -> int | None:
        """Close the oldest live client connection abruptly; its number, or None if none.

        The oldest, so the clients take turns: a reset one reconnects as the newest."""
        live = self.live()
        if not live:
            return None
        conn = live[0]
        conn.close(abrupt=True)
        with self.lock:
            self.stats.resets += 1
            self.reset_log.append((time.time(), conn.n))
        return conn.n

    def hold(self, seconds: float) -> None:
        """A cut on loopback: for ``seconds`` nothing is read or delivered either way, yet no
        connection closes (the bytes wait in the senders' socket buffers, as on a cut link)."""
        self.held_until = time.monotonic() + min(seconds, self.max_hold_s)

    def stop(self, timeout: float = 5.0) -> None:
        self.stopping.set()
        with contextlib.suppress(OSError):
            self._listener.close()
        for conn in list(self.conns):
            conn.close(abrupt=False)
        deadline = time.monotonic() + timeout
        for t in self._threads:
            t.join(max(0.0, deadline - time.monotonic()))
        for conn in list(self.conns):
            conn.join(max(0.0, deadline - time.monotonic()))
