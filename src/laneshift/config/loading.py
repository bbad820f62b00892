"""Building a ``RunConfig`` from what users write: YAML, TOML or JSON files with one table per
section, and ``section.field`` overrides (``--set``, strings from the command line), each value
coerced to its field's type by ``_coerce``; and saving one (a run directory's ``config.yaml``).

Room: the contract (shared by every process). May import: the standard library, PyYAML and
``.checks`` and ``.run``.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
import typing
from pathlib import Path
from typing import Any, Literal, Mapping

import yaml

from .checks import ConfigError
from .run import SECTIONS, RunConfig


def _coerce(where: str, typ: Any, value: Any) -> Any:
    """Turn a YAML/TOML/CLI value into ``typ``; strings from the CLI are parsed."""
    origin = typing.get_origin(typ)
    if origin is dict:  # resource maps: YAML/JSON mappings, or '{"GPU": 1}' / 'GPU=1,big_mem=1' from the CLI
        if isinstance(value, str):
            text = value.strip()
            if text.startswith("{"):
                try:
                    value = json.loads(text)
                except json.JSONDecodeError:
                    raise ConfigError(f"{where}: not a JSON mapping, got {value!r}") from None
            else:
                pairs = [p.partition("=") for p in text.split(",") if p.strip()]
                if any(not sep for _, sep, _ in pairs):
                    raise ConfigError(f"{where}: write NAME=AMOUNT[,NAME=AMOUNT] or a JSON mapping, got {value!r}")
                value = {k.strip(): v.strip() for k, _, v in pairs}
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: must be a mapping, got {value!r}")
        _, val_t = typing.get_args(typ)
        return {str(k): _coerce(f"{where}.{k}", val_t, v) for k, v in value.items()}
    if origin is tuple:
        (item,) = {a for a in typing.get_args(typ) if a is not Ellipsis}
        if isinstance(value, str):  # "512,512", or as a list is written in YAML or Python: "[512, 512]"
            text = value.strip()
            if len(text) >= 2 and (text[0], text[-1]) in (("[", "]"), ("(", ")")):
                text = text[1:-1]
            value = [v.strip() for v in text.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: must be a list, got {value!r}")
        return tuple(_coerce(where, item, v) for v in value)
    if typ is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("1", "true", "yes", "on", "0", "false", "no", "off"):
            return value.lower() in ("1", "true", "yes", "on")
        raise ConfigError(f"{where}: must be true or false, got {value!r}")
    if typ is int:
        if isinstance(value, bool):
            raise ConfigError(f"{where}: must be an integer, got {value!r}")
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, str):
            try:
                return int(value.replace("_", ""))
            except ValueError:
                try:  # "2e4" is a common way to write a budget
                    as_float = float(value)
                    if as_float.is_integer():
                        return int(as_float)
                except ValueError:
                    pass
        raise ConfigError(f"{where}: must be an integer, got {value!r}")
    if typ is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                pass
        raise ConfigError(f"{where}: must be a number, got {value!r}")
    if typ is str:
        if isinstance(value, (str, int, float)) and not isinstance(value, bool):
            return str(value)
        raise ConfigError(f"{where}: must be a string, got {value!r}")
    if origin is Literal:  # a choice: the section's __post_init__ names the choices if it is none of them
        if value is False and "off" in typing.get_args(typ):  # YAML 1.1 reads a bare `off` as false
            return "off"
        return value if isinstance(value, str) else _coerce(where, str, value)
    raise ConfigError(f"{where}: unsupported type {typ}")


def build_section(name: str, values: Mapping[str, Any]) -> Any:
    """Build one component config from a mapping, refusing unknown fields and bad types."""
    cls = SECTIONS[name]
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = set(values) - known
    if unknown:
        raise ConfigError(f"{name}.{sorted(unknown)[0]}: unknown field (known: {', '.join(sorted(known))}; "
                          f"`laneshift config fields {name}` says what each does)")
    kwargs = {k: _coerce(f"{name}.{k}", hints[k], v) for k, v in values.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:  # pragma: no cover - guarded by the unknown-field check
        raise ConfigError(f"{name}: {exc}") from None


def read_config_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """Read a YAML (.yaml/.yml), TOML (.toml) or JSON file with one table per component."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"config file {path}: {exc.strerror}") from None
    try:
        if path.suffix == ".toml":
            data = tomllib.loads(text)
        elif path.suffix == ".json":
            data = json.loads(text)
        else:
            data = yaml.safe_load(text) or {}
    except (yaml.YAMLError, tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"config file {path}: not valid {path.suffix.lstrip('.') or 'yaml'}: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path}: top level must be a mapping of sections")
    for section, body in data.items():
        if section not in SECTIONS:
            raise ConfigError(f"config file {path}: unknown section {section!r} (known: {', '.join(SECTIONS)})")
        if not isinstance(body, dict):
            raise ConfigError(f"config file {path}: section {section!r} must be a mapping")
    return data


def load_run_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None,
                    base: RunConfig | None = None) -> RunConfig:
    """File values over ``base`` (defaults), then ``overrides`` ({"section.field": value}) on top."""
    merged: dict[str, dict[str, Any]] = (base or RunConfig()).to_dict()
    if path is not None:
        for section, body in read_config_file(path).items():
            merged[section].update(body)
    for dotted, value in (overrides or {}).items():
        section, _, name = dotted.partition(".")
        if section not in SECTIONS or not name:
            raise ConfigError(f"{dotted}: overrides are written section.field (sections: {', '.join(SECTIONS)})")
        merged[section][name] = value
    return RunConfig(**{name: build_section(name, body) for name, body in merged.items()})


def save_run_config(cfg: RunConfig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    return path
