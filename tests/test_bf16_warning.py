"""bfloat16 on a CPU without bfloat16 instructions: ``laneshift.cpus.has_bf16_instructions`` reads
/proc/cpuinfo's flags, ``learner.cpus.bf16_warning`` words the learner's one line, and the learner
prints it when it builds its network (torch emulates bfloat16 there: SmallCNN's update ran 10x
slower than in float32 on an AMD EPYC without avx512_bf16).

Room: tests, unit. May import: laneshift (any floor), pytest, torch, the standard library, tests/fakelinks.py."""

from __future__ import annotations

import importlib.util
import sys
import threading
from pathlib import Path

import pytest
import torch

from laneshift import wire
from laneshift.config import LearnerConfig, load_run_config
from laneshift.cpus import has_bf16_instructions
from laneshift.envspec import EnvSpec
from laneshift.learner import cpus as learner_cpus
from laneshift.learner.cpus import bf16_warning
from laneshift.learner.loop import Learner

# tests/ is not a package and pytest runs with --import-mode=importlib: load the helper by path.
_spec = importlib.util.spec_from_file_location("laneshift_tests_fakelinks", Path(__file__).with_name("fakelinks.py"))
fakelinks = importlib.util.module_from_spec(_spec)
sys.modules.setdefault(_spec.name, fakelinks)
_spec.loader.exec_module(fakelinks)

ZEN3 = "processor\t: 0\nmodel name\t: AMD EPYC\nflags\t\t: fpu sse sse2 avx avx2 fma f16c vaes\n"
ZEN4 = "processor\t: 0\nflags\t\t: fpu avx avx2 avx512f avx512_bf16 avx512_vnni\n"
SAPPHIRE_RAPIDS = "flags\t\t: avx512f amx_tile amx_bf16 amx_int8\n"
GRAVITON3 = "processor\t: 0\nFeatures\t: fp asimd sve bf16 i8mm\n"


@pytest.mark.parametrize("cpuinfo, expected", [(ZEN3, False), (ZEN4, True), (SAPPHIRE_RAPIDS, True),
                                               (GRAVITON3, True), ("processor\t: 0\n", None), ("", None)])
def test_the_cpu_flags_tell_whether_bfloat16_is_in_hardware(cpuinfo, expected):
    assert has_bf16_instructions(cpuinfo) is expected


def test_this_machine_gives_an_answer_or_none():
    assert has_bf16_instructions() in (True, False, None)


def test_the_warning_names_the_options_that_ask_for_bf16_and_only_where_the_cpu_lacks_it(monkeypatch):
    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    both = LearnerConfig(cnn_precision="bf16", mlp_precision="bf16")
    monkeypatch.setattr(learner_cpus, "has_bf16_instructions", lambda: False)
    line = bf16_warning(both, cpu)
    assert line is not None and "learner.cnn_precision=bf16 and learner.mlp_precision=bf16" in line
    assert "fp32" in line and "\n" not in line
    assert "learner.cnn_precision" not in bf16_warning(LearnerConfig(mlp_precision="bf16"), cpu)
    assert bf16_warning(LearnerConfig(), cpu) is None  # fp32: nothing to say
    assert bf16_warning(both, cuda) is None  # a GPU learner: the CPU's flags do not matter
    monkeypatch.setattr(learner_cpus, "has_bf16_instructions", lambda: True)
    assert bf16_warning(both, cpu) is None
    monkeypatch.setattr(learner_cpus, "has_bf16_instructions", lambda: None)
    assert bf16_warning(both, cpu) is None  # /proc/cpuinfo cannot tell: no guess


@pytest.mark.parametrize("has_bf16, warned", [(False, True), (True, False)])
def test_the_learner_prints_the_line_when_it_builds_its_network(tmp_path, monkeypatch, capsys, has_bf16, warned):
    monkeypatch.setattr(learner_cpus, "has_bf16_instructions", lambda: has_bf16)
    cfg = load_run_config(overrides={"learner.hidden": [8], "learner.mlp_precision": "bf16", "learner.device": "cpu",
                                     "train.run_dir": str(tmp_path)})
    spec = EnvSpec("fake-vectors", wire.TransitionSchema((4,), "<f4", 9), ())
    Learner(cfg, spec, fakelinks.QuietLinks(), threading.Event())
    out = capsys.readouterr().out
    assert ("learner: learner.mlp_precision=bf16 on a CPU without bfloat16 instructions" in out) is warned
