"""Seeds: three disjoint ranges, so that no number is measured on a day a choice was made on.

- **training** ``[0, 800 000)``: every episode a training run draws (PPO, the warm start's
  demonstrations, smoke runs); :func:`training_seed` maps any index into it.
- **validation** ``[800 000, 1 000 000)``: days for development choices (tuning a controller,
  comparing training configs); never used for a reported number.
- **test** ``[1 000 000, ...)``: the held-out days of every reported evaluation; episode ``k``
  of an evaluation uses ``EVAL_SEEDS[k]`` unless a seed range is given.
"""

TRAINING_SEED_END = 800_000
VALIDATION_SEED_BASE = TRAINING_SEED_END
EVAL_SEED_BASE = 1_000_000
#: The held-out evaluation seeds, in order (episode k of an evaluation uses EVAL_SEEDS[k]).
EVAL_SEEDS = tuple(range(EVAL_SEED_BASE, EVAL_SEED_BASE + 1000))
#: First seed of the warm start's demonstration days (agents/training/imitation.py), in the
#: training range: ``WARM_START_SEED_BASE + 1000 * train seed + 100 * round + day``.
WARM_START_SEED_BASE = 700_000
#: First seed of the days the ensemble of imitation fits drives before its distillation
#: (agents/training/ensemble.py), in the training range: ``ENSEMBLE_SEED_BASE + 1000 * train
#: seed + day``.
ENSEMBLE_SEED_BASE = 610_000


def training_seed(index: int) -> int:
    """Seed of the ``index``-th training episode (any index), in the training range."""
    return index % TRAINING_SEED_END


def evaluation_seeds(episodes: int, first_seed: int | None = None) -> tuple[int, ...]:
    """The days of an evaluation: ``first_seed .. first_seed + episodes - 1`` when a first seed
    is given (a ``--seeds`` range), else the first ``episodes`` of :data:`EVAL_SEEDS`."""
    if first_seed is not None:
        return tuple(range(first_seed, first_seed + episodes))
    return tuple(EVAL_SEEDS[:episodes])


def seeds_rule(episodes: int, first_seed: int | None = None, range_name: str = "seeds") -> str:
    """How :func:`evaluation_seeds` chose the days, in words for reports and result files:
    ``"<range_name> START:STOP"`` for a seed range, else ``"EVAL_SEEDS[:N] (...)"``."""
    if first_seed is not None:
        return f"{range_name} {first_seed}:{first_seed + episodes}"
    return f"EVAL_SEEDS[:{episodes}] (agents.common.seeds)"


def parse_seed_range(text: str) -> range:
    """``"START:STOP"`` (stop excluded) as a range of evaluation seeds; a range that reaches
    into the training seeds, or an empty or malformed one, raises ``ValueError``."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = int(parts[0]), int(parts[1])
    except ValueError:
        raise ValueError(f"seed range {text!r}: expected START:STOP, e.g. 1000100:1000150") from None
    if stop <= start:
        raise ValueError(f"seed range {text!r}: STOP must be greater than START")
    if start < TRAINING_SEED_END:
        raise ValueError(f"seed range {text!r} reaches into the training seeds [0, "
                         f"{TRAINING_SEED_END}); evaluate on validation seeds "
                         f"[{VALIDATION_SEED_BASE}, {EVAL_SEED_BASE}) or test seeds "
                         f">= {EVAL_SEED_BASE}")
    return range(start, stop)
