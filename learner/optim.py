"""The learner's Adam: torch's own Adam (fused on CPU and CUDA), without importing ``torch._dynamo``.

Why: torch.optim imports ``torch._dynamo`` (and with it sympy and the inductor's config) the first
time an optimizer is built or stepped, only to mark its methods as not to be traced by
``torch.compile``. The learner never compiles. On the 2-core dev machine that import was 1.1 s of
the learner's start-up, on the path to the first weights every env worker waits for, and 73 MB
of the learner's RSS (``Adam()`` right after ``import torch``: 1.06-1.12 s, 218 -> 291 MB; with
``EagerAdam`` 0.01 s, 232 MB; docs/performance.md).

How, without changing one number torch computes:

1. torch's ``_disable_dynamo`` wrapper (``torch/_compile.py``) keeps the disabled function on the
   wrapped one, ``fn.__dynamo_disable``, the first time it runs, and imports ``torch._dynamo`` to
   make it. That cache is filled here with the function itself, which is what the disabled
   function runs when nothing is being compiled. It covers ``Optimizer.add_param_group``,
   ``zero_grad``, ``state_dict``, ``load_state_dict`` and the functional ``adam``.
2. ``Adam.step``'s decorator imports ``torch._dynamo`` on every call for two graph breaks, which
   matter only while compiling. ``EagerAdam.step`` runs the undecorated step under the same grad
   mode the decorator sets (``defaults["differentiable"]``).

A torch whose internals have another shape is left alone: then ``EagerAdam`` is torch's Adam,
import included (``tests/test_learner_optim.py`` checks the import is avoided in this torch, and
that the parameters after many updates are bitwise those of ``torch.optim.Adam``). A process that
does compile (the learner does not) should use ``torch.optim.Adam``: the methods above would no
longer be kept out of its graphs.

Room: learner (component). May import: torch.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import torch

_DISABLE_CACHE = "__dynamo_disable"  # torch/_compile.py's cache attribute on the wrapped function


def _wrapped_by_disable_dynamo(func: Any) -> list[Callable]:
    """The functions under ``torch._disable_dynamo`` wrappers reachable from ``func`` (through
    ``functools.wraps``' ``__wrapped__`` and the optimizers' ``disabled_func`` closures)."""
    found: list[Callable] = []
    while func is not None:
        code = getattr(func, "__code__", None)
        cells = dict(zip(code.co_freevars, func.__closure__ or ())) if code is not None else {}
        if code is not None and code.co_name == "inner" and code.co_filename.endswith("_compile.py") and "fn" in cells:
            found.append(cells["fn"].cell_contents)
        if "disabled_func" in cells:  # torch.optim.optimizer._disable_dynamo_if_unsupported
            found += _wrapped_by_disable_dynamo(cells["disabled_func"].cell_contents)
        func = getattr(func, "__wrapped__", None)
    return found


def _fill_disable_caches() -> bool:
    """Step 1 of the module's docstring; True when every method the learner calls was covered."""
    optimizer = torch.optim.Optimizer
    targets = (optimizer.add_param_group, optimizer.zero_grad, optimizer.state_dict, optimizer.load_state_dict,
               getattr(importlib.import_module("torch.optim.adam"), "adam", None))
    covered = 0
    for target in targets:
        fns = _wrapped_by_disable_dynamo(target)
        for fn in fns:
            if getattr(fn, _DISABLE_CACHE, None) is None:
                setattr(fn, _DISABLE_CACHE, fn)
        covered += bool(fns)
    return covered == len(targets)


_UNDECORATED_STEP = getattr(torch.optim.Adam.step, "__wrapped__", None)
#: Whether this torch has the shape the module's docstring describes; if not, ``EagerAdam`` is
#: torch's Adam as it is (a cache filled meanwhile changes nothing while nothing compiles).
AVOIDS_DYNAMO = _UNDECORATED_STEP is not None and _fill_disable_caches()


class EagerAdam(torch.optim.Adam):
    """``torch.optim.Adam`` whose ``step`` skips the compile-only graph breaks (and their import)."""

    if AVOIDS_DYNAMO:
        def step(self, closure: Callable[[], Any] | None = None) -> Any:  # type: ignore[override]
            previous = torch.is_grad_enabled()
            try:
                torch.set_grad_enabled(self.defaults["differentiable"])
                return _UNDECORATED_STEP(self, closure)
            finally:
                torch.set_grad_enabled(previous)
