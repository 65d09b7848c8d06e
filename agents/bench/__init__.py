"""The speed of the simulator and of training (``python -m agents.bench``, ``make bench``):
``workloads`` measures, ``report`` writes the Markdown report, ``cli`` is the command line."""

from agents.bench.cli import main

__all__ = ["main"]
