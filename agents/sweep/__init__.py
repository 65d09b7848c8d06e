"""Sweeps: agents x cases x a grid of config overrides x evaluation days, run through the
execution layer (this machine or a Ray cluster), into one tidy CSV and a figure of each metric
against the swept value (``python -m agents.sweep --help``).

One job per module, each importing only those listed before it:

* ``spec``: the sweep file, its grid points and its episode tasks;
* ``outputs``: the tidy CSV, the summary with bootstrap CIs, the figure, ``sweep.json``;
* ``cli``: input checks, the run and the command line.
"""

from agents.sweep.cli import main, run_sweep
from agents.sweep.outputs import SweepResult, write_outputs
from agents.sweep.spec import SweepSpec, load_sweep, parse_sweep

__all__ = ["SweepResult", "SweepSpec", "load_sweep", "main", "parse_sweep", "run_sweep",
           "write_outputs"]
