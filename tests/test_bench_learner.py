"""`laneshift bench learner`: a tiny CPU run through the real CLI parser returns every JSON field,
and both implementations (DoubleDQN.update and the bare torch loop) update at a positive rate.
No speed thresholds: speed depends on the machine.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import json

import torch

from laneshift.cpus import has_bf16_instructions
from laneshift.tools.bench import learner as bench_learner
from laneshift.tools.cli import build_parser


def test_bench_learner_json_shape(capsys) -> None:
    threads = torch.get_num_threads()
    args = build_parser().parse_args(["bench", "learner", "--device", "cpu", "--seconds", "0.02", "--warmup", "0",
                                      "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert torch.get_num_threads() == threads  # the bench restores the thread count it changed

    assert out["device"] == "cpu" and out["device_name"] and out["torch"] == torch.__version__
    assert out["threads"] == 1 and out["rounds"] == 2 and out["cuda"] is None
    assert out["cpu_bf16"] is has_bf16_instructions()  # the header says whether bf16 cases are emulated
    assert [c["name"] for c in out["cases"]] == [c.name for c in bench_learner.CASES]
    precision = {c["name"]: c["precision"] for c in out["cases"]}
    assert precision["small-b32-bf16"] == precision["mlp512-b256-bf16"] == "bf16" and precision["mlp-b256"] == "fp32"
    nets = {c["name"]: (c["network"], c["obs_shape"], c["obs_dtype"], c["batch"]) for c in out["cases"]}
    assert nets == {"mlp-b256": ("MLPQNetwork", [82], "float32", 256),
                    "mlp512-b256": ("MLPQNetwork", [96], "float32", 256),
                    "mlp-b256-bf16": ("MLPQNetwork", [82], "float32", 256),
                    "mlp512-b256-bf16": ("MLPQNetwork", [96], "float32", 256),
                    "cnn-b32": ("NatureCNN", [4, 100, 100], "uint8", 32),
                    "cnn-b64": ("NatureCNN", [4, 100, 100], "uint8", 64),
                    "small-b32": ("SmallCNN", [4, 100, 100], "uint8", 32),
                    "small-b64": ("SmallCNN", [4, 100, 100], "uint8", 64),
                    "small-b32-bf16": ("SmallCNN", [4, 100, 100], "uint8", 32),
                    "small-b32-bf16-rows": ("SmallCNN", [4, 100, 100], "uint8", 32),
                    "small-b32-rows": ("SmallCNN", [4, 100, 100], "uint8", 32),
                    "small-b128": ("SmallCNN", [4, 100, 100], "uint8", 128),
                    "small-b128-bf16": ("SmallCNN", [4, 100, 100], "uint8", 128)}
    rows = {c["name"]: c["rows"] for c in out["cases"]}  # learner.cnn_rows: the straight road's band
    assert rows["small-b32-bf16-rows"] == rows["small-b32-rows"] == "22:78" and rows["small-b32-bf16"] == ""
    params = {c["name"]: c["params"] for c in out["cases"]}
    assert params["small-b32-bf16-rows"] < params["small-b32-bf16"] / 2
    hidden = {c["name"]: c["hidden"] for c in out["cases"]}
    assert hidden["mlp-b256"] == [256, 256] and hidden["mlp512-b256"] == [512, 512]
    for case in out["cases"]:
        assert case["params"] > 0 and case["n_actions"] == 9
        for impl in ("learner", "bare"):
            fig = case[impl]
            assert fig["updates_per_s"] > 0 and 0 < fig["min"] <= fig["updates_per_s"] <= fig["max"]
            assert fig["rows_per_s"] == fig["updates_per_s"] * case["batch"]
            assert len(fig["rounds"]) == 2
            assert all(r["updates"] >= 1 and r["wall_s"] > 0 and r["updates_per_s"] > 0 for r in fig["rounds"])
        assert case["learner_over_bare"] > 0


def test_bench_learner_table_and_bad_arguments(capsys) -> None:
    assert bench_learner.main(["--device", "cpu", "--seconds", "0.01", "--warmup", "0", "--cases", "mlp-b256"]) == 0
    table = capsys.readouterr().out
    assert "DoubleDQN.update" in table and "mlp-b256" in table and "cnn-b32" not in table
    for bad in (["--rounds", "1"], ["--cases", "nope"], ["--seconds", "0"]):
        try:
            bench_learner.main(["--device", "cpu", *bad])
        except SystemExit as exc:
            assert "bench learner" in str(exc)
        else:
            raise AssertionError(f"{bad} accepted")
