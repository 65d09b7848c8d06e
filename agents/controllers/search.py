"""The wide look-ahead search: more than two candidates, rolled out with the same draws.

With ``candidates=k`` (:class:`~agents.controllers.lookahead_settings.LookaheadSettings`) the
look-ahead (:class:`~agents.controllers.guard.GuardController`) does not check the proposer's
one choice: at every decision that matters it rolls out the rollout policy's own choice and the
proposer's ``k`` most probable legal actions (every legal action where the proposer gives no
probabilities), ``samples`` times each over ``horizon_min`` minutes with the config's gusts and
failures, every candidate meeting the same draws (common random numbers), the rollout policy
flying the fleet after the decision's own step. It takes the candidate that loses the fewest
vehicles on average; among those, the most reward, the rollout policy's choice unless another
earns at least ``reward_margin`` more (0 by default here: any more). With ``confidence=z``
it leaves the rollout policy's choice only for a candidate whose paired gain over it, rollout
by rollout on the same draws (reward less :data:`LOSS_COST` per vehicle lost), has a mean at
least ``z`` standard errors above ``reward_margin``: the candidate with the highest such lower
bound. The maximum of several noisy estimates is biased upwards (the winner's curse), and
without that bound a search with few samples leaves a sound choice for a lucky one
(experiments/wide-search-winners-curse).

This is one step of rollout policy improvement over the rollout policy (Bertsekas's rollout
algorithm, with the proposer pruning the candidates): in expectation over the sampled futures
it does no worse than the rollout policy, up to the horizon and the samples' noise. The
proposer matters only through which candidates it offers: with ``proposer=dispatcher`` and
``candidates`` at least the number of legal actions, the search is the same machinery with no
learned part, the control of any claim that learning helps.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from marl_vertiport.sim.core import VertiportSim

__all__ = ["LOSS_COST", "candidate_actions", "confident_choice", "wide_choice"]

#: The reward a lost vehicle is worth in the candidates' values a teacher reads (``search_q``):
#: more than any reward a day's rollout earns, so that the values order the candidates as the
#: search does, the fewest lost first (the planner's stranding penalty).
LOSS_COST = 1000.0


def candidate_actions(proposer: Any, observation: dict, legal: list[int], k: int,
                      also: int) -> list[int]:
    """``also`` (the rollout policy's choice) and the ``k`` legal actions ``proposer`` finds most
    probable (its ``action_probabilities``), in that order, without repeats, ties in probability
    to the lower action index; ``also`` and every legal action where the proposer has no
    probabilities."""
    probabilities = getattr(proposer, "action_probabilities", None)
    p = None if probabilities is None else probabilities(observation)
    if p is None:
        return [also, *(a for a in legal if a != also)]
    ranked = sorted(legal, key=lambda a: (-float(p[a]), a))
    out = [also]
    for a in ranked:
        if len(out) > k:
            break
        if a not in out:
            out.append(a)
    return out


def confident_choice(runs: dict[int, list[tuple[float, float]]], base: int,
                     candidates: list[int], z: float, margin: float) -> int:
    """Of ``candidates``, the one whose paired gain over ``base`` has the highest lower bound
    (mean less ``z`` standard errors) above ``margin``; ``base`` where none clears it.

    ``runs[a]`` holds action ``a``'s rollouts as (vehicles lost, reward), the ``k``-th of every
    action on the same draws; a gain is the reward less :data:`LOSS_COST` per vehicle lost. With
    one rollout an action (a config without uncertainty) the standard error is 0."""
    def value(a: int) -> np.ndarray:
        r = np.asarray(runs[a], dtype=float).reshape(-1, 2)
        return r[:, 1] - LOSS_COST * r[:, 0]

    own = value(base)
    best, best_bound = base, float(margin)
    for a in candidates:
        if a == base:
            continue
        v = value(a)
        n = min(len(v), len(own))
        gain = v[:n] - own[:n]
        se = float(gain.std(ddof=1)) / np.sqrt(n) if n > 1 else 0.0
        bound = float(gain.mean()) - z * se
        if bound > best_bound:  # strictly: a tie keeps the earlier candidate, or the base
            best, best_bound = a, bound
    return int(best)


def wide_choice(guard: Any, sim: VertiportSim, observation: dict, legal: list[int]) -> int:
    """The wide search's action for the acting vehicle of ``sim`` (module docstring); records
    the candidates' values in ``guard.last_values`` and who the choice came from: the rollout
    policy (``last_deferred``), the proposer's own choice, or another candidate the search found
    better (``last_changed``)."""
    s = guard.settings
    base = int(guard.rollout_policy.act(observation))
    proposed = int(guard.proposer.act(observation))
    candidates = candidate_actions(guard.proposer, observation, legal, s.candidates, base)
    if proposed not in candidates:
        candidates.append(proposed)
    guard.checks += 1
    values, _ = guard.evaluate(sim, candidates, runs=guard._compare_runs)
    guard.last_values = values
    guard.search_q = {a: v[1] - LOSS_COST * v[0] for a, v in values.items()}
    margin = s.reward_margin or 0.0
    if s.confidence > 0:
        best = confident_choice(guard.last_runs, base, candidates, s.confidence, margin)
    else:
        fewest = min(v[0] for v in values.values())
        eligible = [a for a in candidates if values[a][0] <= fewest]
        best = max(eligible, key=lambda a: (values[a][1], a == base))  # a tie goes to the base
        if base in eligible and values[best][1] < values[base][1] + margin:
            best = base
    guard.last_deferred = best == base
    guard.last_changed = best not in (base, proposed)
    if guard.last_deferred:
        guard.deferrals += 1
    if best != proposed:
        guard.changes += 1
    return int(best)
