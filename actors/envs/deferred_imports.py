"""Two of highway-env's imports that laneshift's envs never use, deferred until first touched.

highway-env imports ``pandas`` (for its stock Kinematics observation) and ``matplotlib.pyplot``
(for a plotting helper) when it is imported. laneshift's envs use its roads, lanes and vehicles
only: the vector observation is numpy (``observations.py``) and the frames are drawn by
``rendering.py``. The two cost every env process about 46 MB of RSS and 0.8 s of import
(measured: pandas 33 MB and 0.30 s; pyplot 13 MB and 0.50 s beyond the matplotlib package), and
the matplotlib package itself, which finding pyplot's spec would import, 17 MB and 0.18 s more
(building an env and stepping it 100 times: 66 -> 49 MB, 0.44 -> 0.26 s). Each is registered
now as a ``DeferredModule`` and run on its first attribute access, into the same module object,
so code that does use them gets the real module (``import pandas as pd; pd.DataFrame`` works as
always; running pyplot runs the package first).

Why not ``importlib.util.LazyLoader``: on Python 3.11 its module loads on *any* attribute, and
every later ``import pandas`` statement reads ``__spec__``, so highway-env's own import statements
load it at once. A ``DeferredModule`` answers the attributes its spec set (``__spec__``,
``__name__``, ``__path__``, ...) from its dict, and loads on the first other one, under a lock.

Room: actors (the env-running component). May import: the standard library.
"""

from __future__ import annotations

import importlib.util
import sys
import threading
import types
from typing import Any

#: The matplotlib package before its pyplot: finding pyplot's spec would import the package.
DEFERRED = ("pandas", "matplotlib", "matplotlib.pyplot")
# Reentrant: running pyplot runs the matplotlib package on the same thread, under the same lock.
_lock = threading.RLock()
_running: dict[int, int] = {}  # id of a deferred module whose code runs now -> the running thread


class DeferredModule(types.ModuleType):
    """A module whose code has not run yet: ``__getattr__`` is only called for names missing
    from its dict, which before the load is everything but what ``module_from_spec`` set."""

    def __getattr__(self, attr: str) -> Any:
        if _running.get(id(self)) == threading.get_ident():
            # Its own code is running (on this thread): a name not set yet is missing, as on any
            # partly run module; the import system then falls back to sys.modules.
            raise AttributeError(f"partially initialized module {self.__name__!r} has no attribute {attr!r}")
        with _lock:  # other threads wait for the run to end
            if type(self) is DeferredModule:  # first access (another thread may have run it meanwhile)
                spec = self.__spec__
                spec._initializing, _running[id(self)] = True, threading.get_ident()
                try:
                    spec.loader.exec_module(self)
                finally:
                    spec._initializing = False
                    del _running[id(self)]
                self.__class__ = types.ModuleType
        return getattr(self, attr)


def defer_unused_imports() -> list[str]:
    """Register each of ``DEFERRED`` not yet imported as a ``DeferredModule``; returns those deferred."""
    deferred = []
    for name in DEFERRED:
        if name in sys.modules:
            continue
        spec = importlib.util.find_spec(name)  # a submodule's spec reads its (deferred) parent's __path__
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            continue  # not installed, or a loader without exec_module: imported as usual if ever
        module = importlib.util.module_from_spec(spec)
        module.__class__ = DeferredModule
        sys.modules[name] = module
        parent, _, child = name.rpartition(".")
        if parent:  # as the import system does once a submodule is imported
            setattr(sys.modules[parent], child, module)
        deferred.append(name)
    return deferred


def is_loaded(name: str) -> bool:
    """Whether ``name`` was imported and its code has run (reads no attribute, so runs nothing)."""
    module = sys.modules.get(name)
    return module is not None and type(module) is not DeferredModule


def load_deferred() -> None:
    """Run every deferred module now (before code that may use them from several threads at once,
    e.g. stock highway-env envs in in-process mode)."""
    for name in DEFERRED:
        module = sys.modules.get(name)
        if type(module) is DeferredModule:
            getattr(module, "__version__", None)  # a name the spec did not set: runs the module
