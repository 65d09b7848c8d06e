"""The speed of the simulator and of training (``python -m agents.bench``, ``make bench``), one
module per kind of measure: ``env`` (steps per second under random play and recorded traffic,
the cost against fleet size), ``engine`` (a run's pybullet calls recorded and replayed bare),
``overhead`` (the APIs' floor, a profile), ``planner`` (the look-ahead planner),
``learning`` (vector envs, inference, training, memory; ``child`` runs the last two in
processes of their own), ``compare`` and ``replay`` (the env of two checkouts on one traffic);
``report`` writes the Markdown report, ``cli`` is the command line."""

from agents.bench.cli import main

__all__ = ["main"]
