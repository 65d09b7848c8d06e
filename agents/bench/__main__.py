"""``python -m agents.bench``: see :mod:`agents.bench.cli`."""

import sys

from agents.bench.cli import main

sys.exit(main())
