"""``python -m agents.sweep``: see agents/sweep/cli.py."""

import sys

from agents.sweep.cli import main

sys.exit(main())
