"""Seeds: evaluation never reuses a seed that training can draw.

Training and smoke runs draw episode seeds below ``EVAL_SEED_BASE``; evaluation uses the fixed
list ``EVAL_SEEDS`` at and above it.
"""

EVAL_SEED_BASE = 1_000_000
#: The held-out evaluation seeds, in order (episode k of an evaluation uses EVAL_SEEDS[k]).
EVAL_SEEDS = tuple(range(EVAL_SEED_BASE, EVAL_SEED_BASE + 1000))


def training_seed(index: int) -> int:
    """Seed of the ``index``-th training episode (any index), never an evaluation seed."""
    return index % EVAL_SEED_BASE
