"""Learning curves over training seeds: ``python -m agents.curves`` (``make curves``).

One job per module:

* ``runs``: one training run per (train config, seed), as tasks of the execution layer
  (:mod:`agents.execution`: local processes or a Ray cluster), and the baselines' days;
* ``outputs``: the tidy CSV, the summary over seeds (mean and interquartile mean with 95 %
  bootstrap intervals), the figure and ``curves.json``, written by the driver, atomically;
* ``cli``: the command.
"""
