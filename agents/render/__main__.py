"""``python -m agents.render``: see :mod:`agents.render.cli`."""

import sys

from agents.render.cli import main

sys.exit(main())
