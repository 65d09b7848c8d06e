"""``python -m agents.evaluate``: see :mod:`agents.evaluate.cli`."""

import sys

from agents.evaluate.cli import main

sys.exit(main())
