"""Checks that what the project claims still holds on the machine at hand.

* :mod:`agents.checks.train`: ``marl-vertiport check-train`` (``make check-train``): a fresh
  training run against the shipped checkpoint, paired day by day, with a verdict.
* :mod:`agents.checks.results`: ``marl-vertiport check-results`` (``make check-results``): the
  shipped result files were made with the shipped checkpoint, and their first days replay
  exactly on the code as it is.
"""
