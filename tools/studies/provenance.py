"""Where a study's result came from, and writing it whole: the command line, the git revision of
the code (and whether the checkout had changes), and a file written to a temp name and renamed
(``write_whole``; ``write_json`` for JSON), so a file that exists is complete (a protocol seed's
record says the seed is done).

Room: the tools (studies). May import: the standard library.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any


def command_line() -> str:
    """This process's command line, shell-quoted."""
    return shlex.join(sys.argv)


def git_revision(where: str | Path | None = None) -> dict:
    """``{"revision", "dirty"}`` of the git checkout holding ``where`` (default: this code's); both
    None outside a git checkout or without git."""
    where = Path(where) if where is not None else Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=30)
        if head.returncode != 0:
            return {"revision": None, "dirty": None}
        status = subprocess.run(["git", "status", "--porcelain"], cwd=where, capture_output=True, text=True,
                                timeout=60)
        dirty = bool(status.stdout.strip()) if status.returncode == 0 else None
        return {"revision": head.stdout.strip(), "dirty": dirty}
    except (OSError, subprocess.SubprocessError):
        return {"revision": None, "dirty": None}


def write_whole(path: Path, text: str) -> None:
    """Written whole or not at all: a temp file beside it, renamed over it."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_json(path: Path, data: Any) -> None:
    """Written whole or not at all (a seed's file says it is done)."""
    write_whole(path, json.dumps(data, indent=2))
