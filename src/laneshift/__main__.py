"""``python -m laneshift`` is the ``laneshift`` command."""

from .cli import main

raise SystemExit(main())
