"""What every config section shares: ``ConfigError`` (a refused value, naming its field), ``NAME``
(what a run id, actor name or key segment may be) and the checks the sections run in their
``__post_init__``.

Room: the contract (shared by every process). May import: the standard library only.
"""

from __future__ import annotations

import functools
import re
import typing
from typing import Any, Literal


class ConfigError(ValueError):
    """A configuration value or file was refused; the message names the field."""


#: What a name may be: a run id here, and on the wire every actor name and key segment
#: (``laneshift.wire`` checks with this same rule; it lives here so that reading a config needs
#: neither wire nor numpy).
NAME = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")


def _check(cond: bool, where: str, msg: str, value: Any) -> None:
    if not cond:
        raise ConfigError(f"{where}: {msg}, got {value!r}")


def _choices_text(choices: tuple) -> str:
    return ", ".join(map(str, choices[:-1])) + f" or {choices[-1]}" if len(choices) > 1 else str(choices[0])


@functools.cache
def _literal_fields(cls: type) -> tuple[tuple[str, tuple], ...]:
    """A config section's ``Literal[...]`` fields and their choices (read once per class)."""
    return tuple((name, typing.get_args(typ)) for name, typ in typing.get_type_hints(cls).items()
                 if typing.get_origin(typ) is Literal)


def _check_choices(obj: Any, section: str) -> None:
    """Every ``Literal[...]`` field of a config section holds one of its choices."""
    for name, choices in _literal_fields(type(obj)):
        _check(getattr(obj, name) in choices, f"{section}.{name}", f"must be {_choices_text(choices)}",
               getattr(obj, name))


def row_window(text: str) -> tuple[int, int] | None:
    """``"FIRST:END"`` -> (FIRST, END) with 0 <= FIRST < END (learner.cnn_rows); None if it is not one.

    >>> row_window("26:74"), row_window("74:26"), row_window("26")
    ((26, 74), None, None)
    """
    m = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*", str(text))
    if m is None or int(m.group(1)) >= int(m.group(2)):
        return None
    return int(m.group(1)), int(m.group(2))
