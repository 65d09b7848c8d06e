"""``python -m agents.train``: train the GCN ATC (see agents/gcn/training.py)."""

import sys

from agents.gcn.training import main

if __name__ == "__main__":
    sys.exit(main())
