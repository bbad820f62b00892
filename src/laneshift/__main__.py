"""``python -m laneshift`` is the ``laneshift`` command: the one module of ``src/laneshift`` that is
not contract, because Python looks for ``laneshift/__main__.py`` here. It only hands over to
``laneshift.tools.cli``.

Room: the tools (python -m laneshift). May import: anything in laneshift."""

from laneshift.tools.cli import main

raise SystemExit(main())
