"""``python -m agents.train``: train the GCN ATC (see agents/gcn/train/pipeline.py)."""

import sys

from agents.gcn.train.pipeline import main

if __name__ == "__main__":
    sys.exit(main())
