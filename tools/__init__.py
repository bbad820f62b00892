"""The tools: what a person runs on top of the library, the floor above everything else.

``cli`` (the ``laneshift`` command) with ``argtypes`` (the argparse types every command shares) and
``config_reference`` (``laneshift config``); ``studies/`` (evaluation, experiments, the paper's
protocol, plots); ``bench/`` (every benchmark: the ``laneshift bench`` commands and the scripts
that run outside them); ``demos/`` (making demo shards: the writer, the scripted and human-like
generators, the keyboard recorder, ``laneshift demos``). The shard format they write is contract
(``laneshift.demos``). Nothing below this floor imports it, except ``laneshift.deploy``, which may
use the demo generator to make a run's default demo shard (tests/test_import_graph.py).

Room: the tools. May import: anything in laneshift.
"""
