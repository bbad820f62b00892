"""Every benchmark of laneshift lives here, one home: what measures sits beside the command that
runs it, on the tools' floor, apart from the library it measures and from the tests (which check
and never time).

- The ``laneshift bench`` commands, one module each: ``env``, ``replay`` (with
  ``replay_publisher``, ``replay_harness``, ``replay_report``), ``shards``, ``learner``,
  ``worker``, ``run``, ``run_vs_bound``, ``suite`` (``bench all``) and ``report`` (the performance
  table from ``bench all``'s JSON); ``cpu_meter`` is what they share.
- ``scripts/``: benchmarks that cannot run as a ``laneshift bench`` command, so they are scripts
  run by path from a checkout and not part of the installed package (no ``__init__``): the peers,
  each in its own venv whose pins laneshift's cannot share (``rllib_dqn.py``, ``make bench-rllib``;
  ``reverb_replay.py``, ``make bench-reverb``; ``bench all`` runs both where their venvs exist),
  and the measurements that need root and network namespaces or a hostile client (``twohost_run.py``,
  ``twohost_shards.py`` on the tests' two-host harness; ``flood.py``).

Room: the tools (benchmarks). May import: anything in laneshift.
"""
