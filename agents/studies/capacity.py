"""Whether a vertiport carries its fleet, from its config alone (``marl-vertiport capacity``).

It plays no day: it derives each vertiport's capacity (:mod:`marl_vertiport.sim.capacity`: the
turn gap, a trip's energy and minutes, the charging ports' utilisation, what a turn gap costs
hovering and idling) and prints *carried*, *marginal* or *overloaded* with the numbers behind
the verdict::

    marl-vertiport capacity paper paper_overloaded large

Where the charging ports' minutes go on simulated days is the charger study,
``marl-vertiport charger-study`` (:mod:`agents.studies.charger_study`); before 0.2.0 it was
``capacity`` with no names, which still runs it, with a note.
"""

from __future__ import annotations

import argparse
import sys

from marl_vertiport import ConfigError
from marl_vertiport.config import load_config
from marl_vertiport.sim.capacity import capacity, table as capacity_table


def main(argv: list[str] | None = None, prog: str = "python -m agents.studies.capacity") -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        from agents.common.names import note_renamed
        from agents.studies import charger_study

        note_renamed(f"{prog} with no names", prog.replace("capacity", "charger-study"),
                     "command")
        return charger_study.main(argv, prog=prog.replace("capacity", "charger-study"))
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("configs", nargs="+", metavar="CONFIG",
                        help="env config names or paths: print each one's capacity, derived "
                             "from the config alone (rules v1)")
    args = parser.parse_args(argv)
    return _analytic(args.configs)


def _analytic(configs: list[str]) -> int:
    """Print the capacity of each config (``marl_vertiport.sim.capacity``); exit 2 on a config
    that does not load."""
    try:
        rows = [capacity(load_config(name)) for name in configs]
    except (ConfigError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print("Capacity derived from each config (rules v1; no simulated day), "
          "docs/battery-and-uncertainty.md, section 8.3:\n")
    print(capacity_table(rows))
    print()
    for c in rows:
        print(f"{c.name}: {c.verdict}: {c.reason}")
    print("\nThe model counts charging ports, energy and turns, not the separation check's holds: "
          "it calls `wide` and experiments/vertiport-capacity/configs/fleet40_all_pads_charging.yaml "
          "carried, yet both "
          "still lose vehicles; `fleet40` is carried on days too, its departures waiting on "
          "their charging ports and its flight plans asking less "
          "(experiments/vertiport-capacity).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
