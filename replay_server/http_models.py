"""The HTTP inspection API's JSON: numpy-aware, finite-only responses (``SafeJSONResponse``),
observations as lists, and the documented shapes of its answers (pydantic models, used for the
OpenAPI schema only).

Room: replay_server (component). May import: numpy, fastapi, pydantic.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field


TABLES = ("online", "demo")
DEFAULT_LIMIT = 10
MAX_LIMIT = 100


def _np_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")


def _finite(obj: Any) -> Any:
    """``obj`` with numpy values made plain and NaN / inf replaced by None (JSON has neither)."""
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (np.generic, np.ndarray)):
        return _finite(_np_default(obj))
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


class SafeJSONResponse(JSONResponse):
    """JSON that never fails on numpy values or non-finite floats (those become null)."""

    def render(self, content: Any) -> bytes:
        try:
            text = json.dumps(content, allow_nan=False, default=_np_default, separators=(",", ":"))
        except ValueError:  # a NaN or inf somewhere (e.g. in shard metadata): the slow path
            text = json.dumps(_finite(content), allow_nan=False, separators=(",", ":"))
        return text.encode("utf-8")


SHORT_FLOATS_MAX = 200_000  # numbers per page up to which float32 obs are written in their shortest form


def _obs_lists(arr: np.ndarray) -> list:
    """Rows of ``arr`` as nested lists; float32 / float16 in their shortest decimal form (0.2, not
    0.20000000298023224) when the page is small enough for that (numpy's shortest repr is ~1 us a number)."""
    if arr.dtype.kind == "f" and arr.dtype.itemsize < 8 and arr.size <= SHORT_FLOATS_MAX:
        arr = arr.astype(str).astype(np.float64)  # shortest repr, parses back to the same float32 bits
    return arr.tolist()


def _f32(x: Any) -> float:
    """A float32 as its shortest decimal (0.1, not 0.10000000149011612); parses back bit-exact."""
    return float(str(np.float32(x)))


# --------------------------------------------------------------------------- documented shapes (OpenAPI only)


class Health(BaseModel):
    status: str = Field(description="ok, or unavailable (503) when the core's lock was not free within 2 s")
    mode: str
    phase: int
    uptime_s: float
    online_size: int


class Item(BaseModel):
    key: int = Field(description="online: the item's global insertion key; demo: its row in the demo table "
                                 "(the index a sampled batch reports for demo rows)")
    action: int
    reward: float = Field(description="the discounted sum of `steps` rewards (1 = an ordinary transition)")
    steps: int = Field(description="rewards summed in `reward`; the learner bootstraps with gamma ** steps")
    terminated: bool
    truncated: bool | None = Field(None, description="online only")
    actor: str | None = Field(None, description="online only: the actor that sent the item")
    weights_version: int | None = Field(None, description="online only: the weights version that acted")
    priority: float | None = Field(None, description="prioritized sampler only: the item's sampling mass "
                                                    "(priority ** alpha; 0 = not sampled)")
    obs: list | None = Field(None, description="only with include_obs=true")
    next_obs: list | None = Field(None, description="only with include_obs=true")


class ItemsPage(BaseModel):
    table: str
    offset: int
    limit: int = Field(description="the limit applied (the one asked for, at most 100)")
    total: int = Field(description="items in the table when the page was read")
    oldest_key: int | None
    newest_key: int | None
    next_offset: int | None = Field(description="offset of the next page, null on the last one")
    include_obs: bool
    obs_shape: list[int]
    obs_dtype: str
    items: list[Item]


class Problem(BaseModel):
    detail: Any


class Info(BaseModel):
    wire_version: int = Field(description="the wire version this server speaks (docs/wire.md)")
    obs_shape: list[int] = Field(description="shape of one observation: TRANSITIONS carry obs [B, *obs_shape]")
    obs_dtype: str = Field(description="numpy little-endian code of obs and next_obs, e.g. <f4 or |u1")
    n_actions: int = Field(description="actions are integers in [0, n_actions)")
    run_id: str | None = Field(description="transport.run_id: keys are laneshift/<run_id>/...")
    mode: str = Field(description="replay.demo_mode")
    http_url: str | None = Field(description="this API's address as the server announces it, null if off")
