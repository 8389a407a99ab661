"""The last stage of the structure choice: index sets compared by their output-error refined models.

:func:`~ssme_envs.identification.structure.explore` scores index sets by the held-out simulation
error of their instrumental-variable (or least-squares) estimates. Two things make those scores
a poor guide on their own:

- A weakly observable mode's estimate is noisy, and a larger set can score better only because
  its extra parameters soak up that noise: :func:`refine_contenders` rescores the close
  contenders after refining each (:func:`~ssme_envs.identification.output_error.refine`).
- An estimate can simulate worse with one state more than with one less, so a walk on first
  scores stops short of the system's order (a random 10-state system at 1e-6 output noise: first
  scores best at 4 states, refined ones at 10): :func:`walk_refined` walks on refined scores.

The chosen set's model is its estimate, not the refined model, so a refined score counts only
where the set's estimate is itself close to the best estimate (:func:`settle`): a set whose
estimate is poor (a structure the instrumental variables cannot fit, one short of the system)
is not chosen for what refinement would have made of it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ssme_envs.identification.output_error import CRITERION_FLOOR, held_out_criterion, refine
from ssme_envs.identification.structure import Candidate, StructureSearch, neighbours
from ssme_envs.models.statespace import AlphaCanonicalModel

# Candidates within this criterion of the best are refined by output error before the choice
# (a BIC difference of 200 is far beyond what estimation noise alone moves), at most this many;
# and a refined score counts only for a set whose estimate scores within it of the best estimate.
REFINE_MARGIN = 200.0
MAX_CONTENDERS = 4
# Steps of the walk on refined scores (each refines up to two sets per output).
MAX_REFINED_WALK = 12
# Steps the walk goes on past a best that no neighbour improves on, to larger sets only.
PATIENCE = 1
NOT_COUNTED = "refined score not counted: the estimate of this set is far from the best estimate"


def refine_candidate(
    cand: Candidate, model: AlphaCanonicalModel, u: np.ndarray, y: np.ndarray, split: int
) -> None:
    """Rescore ``cand`` (fitted as ``model`` on the samples before ``split``) by its model refined
    on them, in place, keeping its first score in ``cand.unrefined``, and mark it refined; one
    already at the round-off floor has nothing to gain and keeps its score."""
    floor = CRITERION_FLOOR * np.std(y, axis=0)  # the floor held_out_criterion applies
    if not cand.refined and not np.all(np.array(cand.rms_error) <= floor):
        cand.unrefined = (cand.criterion, cand.rms_error)
        refined = refine(model, u[:split], y[:split])
        cand.criterion, cand.rms_error = held_out_criterion(refined, cand.parameters, u, y, split, True)
        cand.note = "output-error refined"
    cand.refined = True


def refine_contenders(search: StructureSearch, refine_one: Callable[[Candidate], None]) -> None:
    """Rescore the candidates within ``REFINE_MARGIN`` of the best (at most ``MAX_CONTENDERS``)
    by ``refine_one`` (:func:`refine_candidate` on the set's estimate), and choose again."""
    ranked = search.ranked()
    if not ranked:
        return
    for cand in ranked[:MAX_CONTENDERS]:
        if cand.criterion <= ranked[0].criterion + REFINE_MARGIN:
            refine_one(cand)
    search.indices = search.ranked()[0].indices


def walk_refined(
    search: StructureSearch,
    score: Callable[[tuple[int, ...]], Candidate],
    refine_one: Callable[[Candidate], None],
) -> None:
    """From the best candidate, one output's index up or down at a time, on refined scores, then
    :func:`settle`.

    Where no neighbour improves on the best, the walk goes on up to ``PATIENCE`` steps from the
    best larger neighbour: refined scores can stay level for a state or two before falling to the
    system's order (a 10-state system: 4 and 5 states within 11 units, 6 states 2900 below). A
    smaller neighbour whose first score is beyond ``REFINE_MARGIN`` of the best first score is not
    refined: :func:`settle` would not count its refined score, and no walk goes on from it.
    ``score(indices)`` gives a new set's candidate with its first score; ``refine_one(candidate)``
    refines a scored one in place (:func:`refine_candidate`)."""
    by_indices = {c.indices: c for c in search.candidates}
    ranked = search.ranked()
    if not ranked:
        return
    current, best, stale = ranked[0], None, 0
    for _ in range(MAX_REFINED_WALK):
        moves = [by_indices.get(mu) or score(mu) for mu in neighbours(current.indices)]
        for cand in moves:
            if cand.indices not in by_indices:
                search.candidates.append(cand)
                by_indices[cand.indices] = cand
        bound = min(_first(c) for c in search.candidates) + REFINE_MARGIN
        for cand in (current, *moves):
            larger = sum(cand.indices) > sum(current.indices)
            if np.isfinite(cand.criterion) and (cand is current or larger or _first(cand) <= bound):
                refine_one(cand)
        top = search.ranked()[0]
        if top is not best:
            current, best, stale = top, top, 0
            continue
        larger = [c for c in moves if sum(c.indices) > sum(current.indices) and np.isfinite(c.criterion)]
        stale += 1
        if stale > PATIENCE or not larger:
            break
        current = min(larger, key=lambda c: c.criterion)
    settle(search)


def _first(cand: Candidate) -> float:
    """The candidate's first score (before any refinement); inf where it could not be fitted."""
    first = cand.unrefined[0] if cand.unrefined else cand.criterion
    return first if np.isfinite(first) else float("inf")


def settle(search: StructureSearch) -> None:
    """Give back their first scores to the refined candidates whose first score is more than
    ``REFINE_MARGIN`` above the best first score (noted :data:`NOT_COUNTED`), and set
    ``search.indices`` to the best."""
    firsts = [_first(c) for c in search.candidates]
    if not np.isfinite(min(firsts, default=float("inf"))):
        return
    for cand, first in zip(search.candidates, firsts, strict=True):
        if cand.unrefined and first > min(firsts) + REFINE_MARGIN:
            cand.criterion, cand.rms_error = cand.unrefined
            cand.unrefined, cand.note = None, NOT_COUNTED
    search.indices = search.ranked()[0].indices


__all__ = ["MAX_CONTENDERS", "REFINE_MARGIN", "refine_candidate", "refine_contenders", "walk_refined"]
