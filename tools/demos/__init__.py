"""The demo tools: what makes demo shards (``writer``, ``generate`` with ``drivers`` and the
``humanlike`` stand-in, ``record`` with ``keys`` and ``screenshot`` for a person at the keyboard)
and looks into them (``inspection``), and ``laneshift demos`` (``cli``). The shard format they
write and read is the contract's ``laneshift.demos``. Import the module you need
(``from laneshift.tools.demos.generate import generate_shard``): this package imports nothing, so
reading one tool does not load the env-running generator.

Room: the tools (demo tools). May import: anything in laneshift.
"""
