"""The cluster placement check that runs before a cluster run creates any actor: a component no
node can hold, a cluster too small in total, a packing that may fail, and a run that fits.

Room: tests, unit. May import: laneshift.deploy.placement_check, pytest, the standard library."""

from __future__ import annotations

from laneshift.deploy.placement_check import Need, check_placement


def _run(workers: int, worker_cpus: float = 1.0, learner: dict | None = None) -> list[Need]:
    return [Need("router", {"CPU": 0.0}), Need("replay-server", {"CPU": 1.0}),
            Need("learner", learner or {"CPU": 1.0}), *(Need(f"w{i}", {"CPU": worker_cpus}) for i in range(workers))]


def test_a_run_that_fits_passes():
    assert check_placement(_run(2), [{"CPU": 4.0}]).refusal is None
    v = check_placement(_run(6), [{"CPU": 4.0}, {"CPU": 4.0}])
    assert v.refusal is None and v.warning is None


def test_too_few_cpus_in_total_is_refused_with_the_breakdown():
    v = check_placement(_run(8), [{"CPU": 4.0}, {"CPU": 2.0}])
    assert v.refusal == ("the run needs 10 CPU (router 0, replay-server 1, learner 1, workers 8) and the cluster has 6 "
                         "on 2 nodes: fewer workers (--workers) or smaller deploy.*_cpus / *_resources, or a larger "
                         "cluster")


def test_a_component_that_fits_no_node_is_named():
    v = check_placement(_run(1, learner={"CPU": 1.0, "GPU": 1.0}), [{"CPU": 8.0}, {"CPU": 8.0}])
    assert v.refusal.startswith("learner needs 1 CPU, 1 GPU on one node, and no node has that (the largest: 8 CPU")
    v = check_placement(_run(1, learner={"CPU": 1.0, "laneshift_learner": 1.0}), [{"CPU": 8.0}])
    assert "learner needs 1 CPU, 1 laneshift_learner on one node" in v.refusal
    assert check_placement(_run(1), []).refusal == "the Ray cluster has no alive node"


def test_totals_that_cover_the_run_but_pack_badly_give_a_warning_not_a_refusal():
    needs = [Need("learner", {"CPU": 1.5}), Need("w0", {"CPU": 1.5}), Need("w1", {"CPU": 1.5})]
    v = check_placement(needs, [{"CPU": 2.5}, {"CPU": 2.5}])
    assert v.refusal is None and "no packing found here places" in v.warning and "Ray may still find one" in v.warning
