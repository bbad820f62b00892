"""The argparse pieces every command shares: the number types (``positive_int``,
``non_negative_int``, ``positive_float``, ``non_negative_float``, ``fraction``), ``comma_list``,
``endpoint`` (a zenoh endpoint), ``new_file`` (an output file in an existing folder), ``seed_list`` (the studies' ``--seeds``), the
``--set SECTION.FIELD=VALUE`` option (``add_set_arg``, ``parse_set``) and the ``--config`` file with
it (``add_config_args``, and ``config_from``: the run config they give). A bad value is an ``argparse.ArgumentTypeError`` naming what was expected, which
the parser turns into one line and exit code 2.

The ``laneshift`` command (``laneshift.tools.cli``) and the sub-commands it registers (the studies, the
benchmarks, the demo tools) import them from here, never from ``laneshift.tools.cli``, which imports them.

    >>> positive_int("3"), comma_list(positive_int, "integers >= 1")("1, 4,16")
    (3, [1, 4, 16])

Room: the tools (argparse helpers). May import: the contract (``laneshift.config``) and the standard
library.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from laneshift.config import ConfigError, RunConfig, load_run_config


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    return _checked(int, text, lambda v: v >= 1, "an integer >= 1")


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    return _checked(int, text, lambda v: v >= 0, "an integer >= 0")


def positive_float(text: str) -> float:
    """argparse type: a number > 0."""
    return _checked(float, text, lambda v: v > 0 and v != float("inf"), "a number > 0")


def non_negative_float(text: str) -> float:
    """argparse type: a number >= 0."""
    return _checked(float, text, lambda v: 0 <= v < float("inf"), "a number >= 0")


def fraction(text: str) -> float:
    """argparse type: a number in [0, 1]."""
    return _checked(float, text, lambda v: 0.0 <= v <= 1.0, "a number from 0 to 1")


def _checked(kind: type, text: str, ok: Any, what: str) -> Any:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not ok(value):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


def comma_list(kind: Any, what: str) -> Any:
    """argparse type: a non-empty comma-separated list, each item through ``kind`` (a type or an
    argparse type function)."""

    def parse(text: str) -> list:
        items = [item.strip() for item in text.split(",") if item.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}, got {text!r}")
        try:
            return [kind(item) for item in items]
        except (ValueError, argparse.ArgumentTypeError):
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}, got {text!r}") from None

    parse.__name__ = f"list of {what}"
    return parse


def endpoint(text: str) -> str:
    """argparse type: a zenoh endpoint, PROTOCOL/ADDRESS (tcp/127.0.0.1:7447)."""
    proto, sep, address = text.partition("/")
    if not sep or not proto.isalnum() or not address:
        raise argparse.ArgumentTypeError(f"expected a zenoh endpoint like tcp/127.0.0.1:7447, got {text!r}")
    return text


def new_file(text: str) -> Path:
    """argparse type: a file to write, in a folder that exists (checked before any work is done)."""
    path = Path(text)
    if path.is_dir() or not path.resolve().parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: not a file in an existing folder")
    return path


def parse_set(items: list[str]) -> dict[str, str]:
    """``--set SECTION.FIELD=VALUE`` items as overrides; a malformed one is a ConfigError."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: write SECTION.FIELD=VALUE, e.g. --set learner.lr=1e-4")
        out[key.strip()] = value
    return out


def add_set_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any config field, e.g. --set learner.lr=1e-4 (repeatable; `laneshift config "
                        "fields TEXT` says what each field does)")


def add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="YAML/TOML/JSON file with sections env, actor, replay, learner, transport, train")
    add_set_arg(p)


def config_from(args: argparse.Namespace, shortcuts: dict[str, Any] | None = None,
                 preset: dict[str, Any] | None = None, base: RunConfig | None = None) -> RunConfig:
    """``--config`` file < ``preset`` (a named method's settings) < flag shortcuts < ``--set``."""
    overrides: dict[str, Any] = dict(preset or {})
    overrides.update({k: v for k, v in (shortcuts or {}).items() if v is not None})
    overrides.update(parse_set(args.set))
    return load_run_config(args.config, overrides, base=base)


def seed_list(text: str) -> list[int]:
    """``--seeds``: comma-separated integers >= 0."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"--seeds: expected comma-separated integers >= 0, got {text!r}")
    return seeds
