"""Observability indices: the row-by-row rank search (NASA TM-104422, eqs 28-33) and its neighbours.

The past outputs ``Q`` (lags ``1..L`` of every output), after their projection on the lagged
inputs ``R`` is removed, span the same row space as the observability matrix (``Q_o = V M V^T``,
eq 31). A row-by-row search over ``C``, ``CA``, ``CA^2``, ... (power by power, outputs in order)
keeps each output's next row while it adds a new direction; the number of rows kept for output
``i`` is ``mu_i``. The projections come from one QR factorization of ``[R Z Q]`` (never from
inverting ``R R^T``). ``Z`` holds older inputs: projecting ``Q`` on them as instruments removes
white measurement noise, so dependent rows shrink towards zero as the record grows while
independent ones do not.

Decision rule: a candidate row is independent when the norm of its component orthogonal to the
rows already kept exceeds ``rank_tol`` (default 0.1) times its own norm. Noise-free data give
ratios near 1e-15 for dependent rows. With noise, a dependent row's ratio grows with the
noise-to-signal ratio over sqrt(N) (about 0.02 for 5 % noise on 1000 samples of the Table I
models), and a weakly observable mode's independent row can sit as low: no threshold separates
the two on every record. So the search also returns the index sets one decision away (the
nearest ratios on either side of the threshold, re-searched with the threshold moved past them),
and :func:`ssme_envs.identification.alpha_canonical.identify` chooses among them by a
criterion on the fitted models.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

DEFAULT_MAX_INDEX = 6
DEFAULT_RANK_TOL = 0.1
# Ratios below this are round-off (noise-free dependent rows): never a candidate decision.
RATIO_FLOOR = 1e-6
# Neighbours always scored: decisions turned to "independent" (larger models; more while the
# score improves) and to "dependent".
STEPS_DOWN = 2
STEPS_UP = 1
# Sets flipped on from at each further step down: the best one alone can lead away from the
# structure (a weak row's neighbour improves first), the runners-up keep the other paths open.
BEAM = 3
# Steps of the walk over single indices from the best set, and the largest order it visits.
MAX_WALK = 6
MAX_WALK_ORDER = 12
# A BIC difference below this is weak evidence (Kass and Raftery 1995: above 10 is very strong).
CLOSE_MARGIN = 10.0


@dataclass
class Candidate:
    """One index set and how its fitted model scored (lower criterion is better)."""

    indices: tuple[int, ...]
    criterion: float = float("nan")
    parameters: int = 0
    rms_error: tuple[float, ...] = ()
    note: str = ""
    refined: bool = False  # its criterion is that of the output-error refined model
    unrefined: tuple[float, tuple[float, ...]] | None = None  # (criterion, rms_error) before refining


@dataclass
class StructureSearch:
    """Outcome of the row-by-row rank search and of the choice among its neighbours.

    Attributes
    ----------
    indices : tuple of int
        The chosen observability indices (the rank rule's unless a neighbour scored better).
    ratios : list of (output, power, ratio, kept)
        For each candidate row ``c_output A^power`` examined at ``rank_tol``: the norm of its new
        component over its norm, and whether it was kept.
    rank_rule : tuple of int
        The indices the rank rule alone gives at ``rank_tol`` (a zero or an open chain when the
        rule alone finds no valid structure).
    candidates : list of Candidate
        Every index set compared, the rank rule's (or its nearest valid neighbour's) first.
    criterion : str
        What the candidates' ``criterion`` is.
    """

    indices: tuple[int, ...]
    ratios: list[tuple[int, int, float, bool]] = field(default_factory=list)
    rank_rule: tuple[int, ...] = ()
    candidates: list[Candidate] = field(default_factory=list)
    criterion: str = ""
    rows: np.ndarray = field(default_factory=lambda: np.empty((0, 0)), repr=False)
    rank_tol: float = DEFAULT_RANK_TOL
    flipped: frozenset[tuple[int, int]] = field(default_factory=frozenset, repr=False)

    def ranked(self) -> list[Candidate]:
        """Candidates that could be fitted, best first."""
        ok = [c for c in self.candidates if np.isfinite(c.criterion)]
        return sorted(ok, key=lambda c: c.criterion)

    @property
    def runner_up(self) -> Candidate | None:
        ranked = self.ranked()
        return ranked[1] if len(ranked) > 1 else None

    @property
    def margin(self) -> float:
        """Criterion of the runner-up minus the chosen one's (inf when there is no runner-up)."""
        ranked = self.ranked()
        return ranked[1].criterion - ranked[0].criterion if len(ranked) > 1 else float("inf")

    @property
    def close(self) -> bool:
        """Whether the runner-up is within ``CLOSE_MARGIN`` of the choice."""
        return self.margin < CLOSE_MARGIN

    def summary(self) -> str:
        """One or two lines for a console: the choice, the runner-up and the margin."""
        text = f"structure: indices {list(self.indices)} chosen by {self.criterion or 'the rank rule'}"
        if self.rank_rule != self.indices:
            text += f" (the rank rule at rank_tol {self.rank_tol:g} alone gave {list(self.rank_rule)})"
        runner = self.runner_up
        if runner is None:
            return text + "; no other index set could be fitted"
        text += f"; runner-up {list(runner.indices)} by {self.margin:.1f}"
        if self.close:
            text += (
                f"\nwarning: the structure choice is close (margin below {CLOSE_MARGIN:g}): check the "
                "structure search in report.md and give the indices with --indices if you know them"
            )
        return text

    def to_dict(self) -> dict:
        """JSON-ready record of the choice (stored in the model's ``fit``)."""
        return {
            "chosen": list(self.indices),
            "rank_rule": list(self.rank_rule),
            "rank_tol": self.rank_tol,
            "criterion": self.criterion,
            "margin": self.margin if np.isfinite(self.margin) else None,
            "candidates": [
                {
                    "indices": list(c.indices),
                    "criterion": c.criterion if np.isfinite(c.criterion) else None,
                    "parameters": c.parameters,
                    "note": c.note,
                }
                for c in self.candidates
            ],
        }


def lagged(x: np.ndarray, lags: Sequence[int], start: int) -> np.ndarray:
    """Columns ``x[k - lag]`` for k = start..T-1, for each lag and each channel (lag-major)."""
    horizon = x.shape[0]
    if not lags:
        return np.empty((horizon - start, 0))
    return np.hstack([x[start - lag : horizon - lag] for lag in lags])


def check_search_length(horizon: int, p: int, n_feat: int, window: int) -> tuple[int, int]:
    """(first usable sample, instrument depth) of a structure search up to index ``window`` on
    ``horizon`` samples of ``p`` outputs and ``n_feat`` input features, or ValueError when the
    record is too short for it."""
    depth = max(window, -(-p * window // n_feat))
    start = window + depth
    needed = (window * n_feat + 1) + depth * n_feat + window * p
    if horizon - start < 2 * needed:
        raise ValueError(
            f"the record has {horizon} samples; a structure search up to index {window} needs at "
            f"least {start + 2 * needed} (use a longer record or a smaller max_index)"
        )
    return start, depth


def instrumented_rows(feats: np.ndarray, y: np.ndarray, window: int) -> np.ndarray:
    """The past outputs with the window's inputs removed, projected on older inputs (orthonormal
    coordinates): column ``k p + i`` carries the row ``c_i A^k``.

    The instruments are the ``depth`` input lags before the window, enough that they can span
    every state the search can find (``p * window``), since a state the instruments cannot
    reach would look like a dependent row.

    Raises
    ------
    ValueError
        For a record too short for the window, or inputs not persistently exciting.
    """
    horizon, p = y.shape
    n_feat = feats.shape[1]
    start, depth = check_search_length(horizon, p, n_feat, window)
    r_block = np.hstack([lagged(feats, range(1, window + 1), start), np.ones((horizon - start, 1))])
    z_block = lagged(feats, range(window + 1, window + depth + 1), start)
    q_block = lagged(y, range(window, 0, -1), start)
    n_r, n_z = r_block.shape[1], z_block.shape[1]
    tri = scipy.linalg.qr(np.hstack([r_block, z_block, q_block]), mode="r", check_finite=False)[0]
    diag = np.abs(np.diag(tri)[: n_r + n_z])
    # each column against its own length (what is left of it beside the columns before): the
    # test of inputs in any units, which the largest diagonal entry (the ones column's, or the
    # inputs', whichever units are larger) is not
    lengths = np.linalg.norm(np.hstack([r_block, z_block]), axis=0)
    if np.any(diag <= 1e-9 * lengths):
        raise ValueError(
            f"the inputs are not persistently exciting over {start} lags (the lagged-input "
            "matrix is rank-deficient): use a richer input such as a PRBS"
        )
    return tri[n_r : n_r + n_z, n_r + n_z :]


def rank_search(
    rows: np.ndarray, p: int, rank_tol: float, flipped: frozenset[tuple[int, int]] = frozenset()
) -> tuple[tuple[int, ...], list[tuple[int, int, float, bool]], bool]:
    """The greedy row search: (indices, ratios, some chain still open at the window's end).

    ``flipped`` rows ``(output, power)`` get the decision opposite to the threshold's.
    """
    window = rows.shape[1] // p
    basis = np.empty((rows.shape[0], 0))
    active = [True] * p
    indices = [0] * p
    ratios: list[tuple[int, int, float, bool]] = []
    for power in range(window):
        for i in range(p):
            if not active[i]:
                continue
            col = rows[:, power * p + i]
            norm = np.linalg.norm(col)
            resid = col - basis @ (basis.T @ col)
            ratio = float(np.linalg.norm(resid) / norm) if norm > 0 else 0.0
            # An output's own row (power 0) is kept unless it repeats the others to round-off:
            # a weak but measured output is still an output (rank_tol judges the shifted rows).
            kept = (ratio > (RATIO_FLOOR if power == 0 else rank_tol)) != ((i, power) in flipped)
            ratios.append((i, power, ratio, kept))
            if kept and ratio > 0:
                basis = np.column_stack([basis, resid / np.linalg.norm(resid)])
                indices[i] += 1
            else:
                active[i] = False
    return tuple(indices), ratios, any(active)


Flips = frozenset[tuple[int, int]]


def flips_from(
    rows: np.ndarray, p: int, rank_tol: float, flipped: Flips, direction: int
) -> list[tuple[Flips, tuple[int, ...] | None]]:
    """Index sets one more decision away: ``direction`` -1 keeps, one at a time, each row the
    threshold cut (larger models); +1 cuts the kept shifted row of smallest ratio. Each comes with
    its flipped rows; None for a structure that is invalid (a chain still open at the window's
    end, an output with no row)."""
    _, ratios, _ = rank_search(rows, p, rank_tol, flipped)
    if direction < 0:
        picks = [(i, k) for i, k, r, kept in ratios if not kept and r > RATIO_FLOOR and (i, k) not in flipped]
    else:
        kept_rows = [(r, i, k) for i, k, r, kept in ratios if kept and k > 0 and (i, k) not in flipped]
        picks = [min(kept_rows)[1:]] if kept_rows else []
    out = []
    for pick in picks:
        new = flipped | {pick}
        indices, _, open_chain = rank_search(rows, p, rank_tol, new)
        out.append((new, None if open_chain or min(indices) == 0 else indices))
    return out


def explore(search: StructureSearch, score: Callable[[tuple[int, ...]], Candidate]) -> None:
    """Score the first candidate and its neighbours, and set ``search.indices`` to the best.

    Downwards (larger models): every set reached by flipping up to ``STEPS_DOWN`` cut rows (a
    flip can make a later row look dependent, so two are needed to reach some structures), then
    on from the ``BEAM`` best while a further flip improves on the best score so far. Upwards:
    ``STEPS_UP`` steps of cutting the weakest kept row. ``score`` returns the candidate with its
    criterion (inf when it cannot be fitted).
    """
    p = len(search.rank_rule)
    scored = {c.indices: score(c.indices) for c in search.candidates}

    def visit(flipped: Flips, direction: int) -> list[tuple[float, list, Flips]]:
        out = []
        for new, indices in flips_from(search.rows, p, search.rank_tol, flipped, direction):
            if indices is not None and indices not in scored:
                scored[indices] = score(indices)
            out.append((scored[indices].criterion if indices is not None else float("inf"), sorted(new), new))
        return out

    level = visit(search.flipped, -1)
    reached = list(level)
    for _ in range(STEPS_DOWN - 1):
        level = [child for *_, flipped in level for child in visit(flipped, -1)]
        reached += level
    if reached:
        best = min(c.criterion for c in scored.values())
        frontier = sorted(reached)[:BEAM]
        for _ in range(search.rows.shape[1]):
            children = [child for *_, flipped in frontier for child in visit(flipped, -1)]
            if not children or min(children)[0] >= best:
                break
            frontier, best = sorted(children)[:BEAM], min(children)[0]
    _walk_indices(scored, score)
    flipped = search.flipped
    for _ in range(STEPS_UP):
        children = visit(flipped, +1)
        if not children:
            break
        flipped = min(children)[2]
    search.candidates = list(scored.values())
    ranked = search.ranked()
    if ranked:
        search.indices = ranked[0].indices


def neighbours(indices: tuple[int, ...]) -> list[tuple[int, ...]]:
    """The index sets one output's index up or down from ``indices``, within ``MAX_WALK_ORDER``."""
    out = []
    for i in range(len(indices)):
        for step in (1, -1):
            mu = list(indices)
            mu[i] += step
            if 1 <= mu[i] and sum(mu) <= MAX_WALK_ORDER:
                out.append(tuple(mu))
    return out


def _walk_indices(
    scored: dict[tuple[int, ...], Candidate], score: Callable[[tuple[int, ...]], Candidate]
) -> None:
    """From the best set, one output's index up or down at a time while that improves the best
    score: reaches structures no single rank decision separates from the best (a weak row of one
    output behind a strong one of another)."""
    for _ in range(MAX_WALK):
        ok = [c for c in scored.values() if np.isfinite(c.criterion)]
        if not ok:
            return
        best = min(ok, key=lambda c: c.criterion)
        moves = [mu for mu in neighbours(best.indices) if mu not in scored]
        for mu in moves:
            scored[mu] = score(mu)
        if not moves or min(scored[mu].criterion for mu in moves) >= best.criterion:
            return


def estimate_indices(
    feats: np.ndarray,
    y: np.ndarray,
    max_index: int = DEFAULT_MAX_INDEX,
    rank_tol: float = DEFAULT_RANK_TOL,
    output_names: Sequence[str] | None = None,
) -> StructureSearch:
    """Observability indices by the row-by-row rank search on Q_o (eqs 28-33), and the index sets
    one decision away as ``candidates``.

    Parameters
    ----------
    feats, y : arrays, shapes (T, m'), (T, p)
        Input features (the inputs, plus |u| of non-binary inputs when lambda is estimated) and
        outputs, already checked.
    max_index : int
        Largest observability index searched (the lag window L).
    rank_tol : float
        Relative norm below which a candidate row counts as dependent.
    output_names : sequence of str, optional
        Used in error messages.
    """
    if max_index < 1:
        raise ValueError(f"max_index must be >= 1, got {max_index}")
    if not 0 < rank_tol < 1:
        raise ValueError(f"rank_tol must be in (0, 1), got {rank_tol}")
    p = y.shape[1]
    names = list(output_names) if output_names is not None else [f"y{i}" for i in range(p)]
    rows = instrumented_rows(feats, y, max_index)
    rank_rule, ratios, open_chain = rank_search(rows, p, rank_tol)
    indices = rank_rule
    if open_chain or min(indices) == 0:
        near = [f for d in (-1, 1) for f in flips_from(rows, p, rank_tol, frozenset(), d) if f[1] is not None]
        if not near:  # nothing near the rank rule's answer is a valid structure either
            i = indices.index(0) if min(indices) == 0 else [r[0] for r in ratios if r[3]][-1]
            if indices[i] == 0:
                raise ValueError(
                    f"output '{names[i]}' adds nothing to the earlier outputs (C is not of full row rank)"
                )
            raise ValueError(
                f"the observability index of output '{names[i]}' exceeds max_index={max_index}: raise "
                "max_index, or the data may be too noisy for the rank tolerance"
            )
        flipped, indices = near[0]
    else:
        flipped = frozenset()
    search = StructureSearch(indices, ratios, rank_rule, [Candidate(indices)], rows=rows, rank_tol=rank_tol)
    search.flipped = flipped
    return search
