"""The configuration reference, read from the config dataclasses themselves: every field of every
section with its type, its default and the comment that explains it in ``laneshift/config.py``.

One source for three readers: ``laneshift config fields [TEXT]`` (the terminal), docs/config.md
(written by ``laneshift config reference``; a test fails when it is stale) and the one-line meaning
that a bad ``--set`` prints next to its error.

Why a reader of source comments instead of ``field(metadata={"doc": ...})``: the comments are already
where a developer reads and edits them, beside the default; a second copy in metadata would drift.
The standard library's ``ast`` and ``tokenize`` read them exactly (no regular expressions over code).

Room: the tools (the laneshift command). May import: laneshift.config and the standard library.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import textwrap
import tokenize
from dataclasses import dataclass

from laneshift.config import SECTIONS


@dataclass(frozen=True)
class FieldDoc:
    """One config field as the reference shows it."""

    section: str
    name: str
    type: str  # as written in the class (e.g. ``Literal["uniform", "prioritized"]``)
    default: object
    doc: str  # the comment lines above the field and the one after it on its line, joined

    @property
    def key(self) -> str:
        return f"{self.section}.{self.name}"


def _comments(source: str) -> dict[int, str]:
    """Line number (1-based, within ``source``) -> the comment's text on that line."""
    out = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out[tok.start[0]] = tok.string.lstrip("#").strip()
    return out


def section_fields(section: str) -> list[FieldDoc]:
    """The fields of one config section (``env``, ``actor`` ...), in the class's order."""
    cls = SECTIONS[section]
    source = textwrap.dedent(inspect.getsource(cls))
    lines = source.splitlines()
    comments = _comments(source)
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    (node,) = ast.parse(source).body
    out = []
    for stmt in node.body:
        if not (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)):
            continue
        name = stmt.target.id
        if name not in defaults:
            continue
        above, line = [], stmt.lineno - 1  # the comment-only lines right above the field
        while line >= 1 and lines[line - 1].strip().startswith("#"):
            above.insert(0, comments.get(line, ""))
            line -= 1
        trailing = comments.get(stmt.end_lineno or stmt.lineno, "")
        doc = " ".join(part for part in [*above, trailing] if part)
        default = defaults[name]
        if default is dataclasses.MISSING:
            default = None
        out.append(FieldDoc(section, name, ast.unparse(stmt.annotation), default, doc))
    return out


def all_fields() -> list[FieldDoc]:
    return [f for section in SECTIONS for f in section_fields(section)]


def find(text: str = "") -> list[FieldDoc]:
    """Fields whose ``section.field`` or meaning contains ``text`` (any case); a section's name
    alone gives that section."""
    text = text.lower().strip()
    if text in SECTIONS:
        return section_fields(text)
    return [f for f in all_fields() if text in f.key.lower() or text in f.doc.lower()]


def _shown(value: object) -> str:
    if isinstance(value, float) and value == float("inf"):
        return "inf"
    if isinstance(value, tuple):
        return "[" + ", ".join(map(str, value)) + "]"
    return repr(value) if isinstance(value, str) else str(value)


def as_text(fields: list[FieldDoc], width: int = 100) -> str:
    """For the terminal: ``section.field: type = default`` and its meaning, indented below."""
    out = []
    for f in fields:
        out.append(f"{f.key}: {f.type} = {_shown(f.default)}")
        if f.doc:
            out += textwrap.wrap(f.doc, width=width, initial_indent="    ", subsequent_indent="    ")
    return "\n".join(out) + "\n"


def as_markdown() -> str:
    """docs/config.md: one table per section."""
    parts = ["# Configuration reference", "",
             "Every field of a run's config: its type, its default and what it does. Set one with "
             "`--set section.field=value` on any command that runs something, or in a YAML/TOML/JSON file "
             "given with `--config` (sections as below). `laneshift config fields TEXT` prints the same from "
             "the terminal; `laneshift config show [--config F] [--set ...]` prints a resolved config. "
             "Method presets (`--method`) are sets of these fields: `laneshift config methods`.", "",
             "This page is generated from the comments beside each field in `src/laneshift/config.py` "
             "(`laneshift config reference > docs/config.md`); a test fails when it is out of date.", ""]
    for section in SECTIONS:
        doc = inspect.getdoc(SECTIONS[section]) or ""
        parts += [f"## `{section}`", "", doc.split("\n\n")[0].replace("\n", " "), "",
                  "| field | type | default | meaning |", "|---|---|---|---|"]
        for f in section_fields(section):
            cell = f.doc.replace("|", "\\|")
            typ = f.type.replace("|", "\\|")
            parts.append(f"| `{f.key}` | `{typ}` | `{_shown(f.default)}` | {cell} |")
        parts.append("")
    return "\n".join(parts)


def meaning(key: str) -> str | None:
    """The one-line meaning of ``section.field`` (None for an unknown one)."""
    section, _, name = key.partition(".")
    if section not in SECTIONS:
        return None
    return next((f.doc for f in section_fields(section) if f.name == name), None)
