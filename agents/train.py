"""``python -m agents.train``: train the GCN ATC (agents/training/cli.py)."""

import sys

from agents.training.cli import main

if __name__ == "__main__":
    sys.exit(main())
