"""``python -m agents.train``: train the GCN ATC (see agents/training/pipeline.py)."""

import sys

from agents.training.pipeline import main

if __name__ == "__main__":
    sys.exit(main())
