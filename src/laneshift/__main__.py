"""``python -m laneshift`` is the ``laneshift`` command.

Room: the tools (python -m laneshift). May import: anything in laneshift."""

from .cli import main

raise SystemExit(main())
