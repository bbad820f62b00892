"""The configuration reference: read from the comments beside the config fields, every field has
a meaning, docs/config.md is current, and ``laneshift config`` prints fields, presets and a
resolved config.

Room: tests, unit. May import: laneshift (any floor), pytest, yaml, the standard library."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from laneshift.tools import cli
from laneshift.config import METHODS, SECTIONS
from laneshift.tools.config_reference import all_fields, as_markdown, find, meaning

DOC = Path(__file__).resolve().parents[1] / "docs" / "config.md"


def test_every_field_of_every_section_is_in_the_reference_with_its_default_and_a_meaning():
    fields = all_fields()
    expected = [f"{s}.{f.name}" for s, cls in SECTIONS.items() for f in dataclasses.fields(cls)]
    assert [f.key for f in fields] == expected
    assert [f.key for f in fields if not f.doc] == []
    lr = next(f for f in fields if f.key == "learner.lr")
    assert (lr.type, lr.default) == ("float", 5e-4)
    # A comment block above a field and the comment after it on its line both count.
    assert meaning("learner.lr_final").startswith("The learning rate at the end of the env-step budget")
    assert meaning("replay.capacity") == "total items, demo region included (retention)"
    assert meaning("learner.nope") is None and meaning("nope.lr") is None


def test_docs_config_md_is_the_generated_reference():
    assert DOC.read_text() == as_markdown(), "docs/config.md is stale: laneshift config reference > docs/config.md"


def test_find_by_section_field_or_word():
    assert {f.section for f in find("replay")} == {"replay"}
    assert "actor.epsilon_final" in {f.key for f in find("epsilon")}
    assert find("no such thing at all") == []


def test_the_config_command(capsys, tmp_path):
    assert cli.main(["config", "fields", "lr_final"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("learner.lr_final: float = 0.0\n    The learning rate at the end")
    assert cli.main(["config", "fields", "zzz-nothing"]) == 2
    assert "no field or meaning contains 'zzz-nothing'" in capsys.readouterr().err
    assert cli.main(["config", "methods"]) == 0
    assert [line.split(":")[0] for line in capsys.readouterr().out.splitlines()] == list(METHODS)
    assert cli.main(["config", "show", "--method", "dqfd-bc-anneal", "--set", "env.scenario=merge"]) == 0
    shown = yaml.safe_load(capsys.readouterr().out)
    assert shown["env"]["scenario"] == "merge" and shown["learner"]["ema_decay"] == 0.999
    # A mistyped field in --set points at the reference.
    assert cli.main(["config", "show", "--set", "learner.lrr=1"]) == 2
    assert "laneshift config fields learner" in capsys.readouterr().err
