"""Test groups. The system tests, which start real Ray clusters, zenoh routers or laneshift
processes (slow: most of the suite's time), carry the ``system`` marker, given here by module so
that a new test in one of these files is in the group without saying so:

    .venv/bin/python -m pytest -m "not system and not chaos"   # the quick unit tests
    .venv/bin/python -m pytest -m system                       # the whole-system tests

``make test`` runs both (``-m "not chaos"``).
Room: tests. May import: pytest.
"""

from __future__ import annotations

import pytest

#: Test modules that start Ray, a zenoh router or laneshift service processes.
SYSTEM_MODULES = {"test_system_local", "test_faults", "test_network_faults", "test_two_host", "test_docs_examples",
                  "test_deploy_files", "test_deploy_kuberay", "test_wait_reporter", "test_cli_errors",
                  "test_experiments", "test_protocol", "test_lka_protocol", "test_chaos_suite", "test_bench_shards",
                  "test_worker_resend", "test_processes_without_ray"}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if item.module is not None else ""
        if module in SYSTEM_MODULES:
            item.add_marker(pytest.mark.system)
