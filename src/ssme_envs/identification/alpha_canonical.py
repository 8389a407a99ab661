"""Structure and parameter identification in alpha-canonical form (NASA TM-104422, eqs 9-47).

Any number of inputs and outputs and any observability indices. The steps (2-4, the fit of one
structure, in :mod:`.alpha_fit`):

1. **Structure** (eqs 28-33): the row-by-row rank search of :mod:`.structure`, then a choice
   among the index sets one or two rank decisions away: each is fitted on the first two thirds
   of the record and scored by the BIC of its simulation error on the last third (the search
   holds every candidate, the runner-up and the margin). The contenders close to the best are
   first refined on their simulation error (:mod:`.output_error`), so that a noisy estimate of a
   weak mode does not hand the choice to a larger structure.

2. **Parameters** (eq 27). Each output's one-step equation ``y_i(k) = theta_i phi_i(k)`` is
   solved by least squares with only the regressors eq 8 leaves free, plus a constant, plus
   the current samples ``y_j(k)`` of earlier outputs with longer chains (``j < i``,
   ``mu_j > mu_i``): the row search lets ``c_i A^mu_i`` depend on ``c_j A^mu_i``, which eq 8's
   pattern leaves out (it covers only the systems without such a dependency). With
   ``method="iv"`` (default) two instrumental-variable passes follow, the instruments being
   the lags of the previous model's simulated output: consistent under white output noise,
   and identical to least squares on noise-free data. A pass is kept only if its model
   simulates the record better, so least squares can stay, biased under white output noise.
   ``method="oe"`` then minimizes the simulation error itself (:mod:`.output_error`): consistent
   under white output noise whatever the passes did, at the cost of an optimization.

3. **Asymmetric gains** (eqs 36-45). For a constant-amplitude (binary) input
   ``u* = u + (lambda - 1) |u|`` is ``u`` plus a constant, so the regression's constant
   equals ``theta_u_bar (Lambda - I) gamma`` (eq 42) and gives lambda exactly. For other
   inputs the lags of ``|u|`` enter the regression and lambda is the least-squares ratio of
   their coefficients to those of ``u``.

4. **Realization**: row ``(i, d)`` of ``[K B]`` is the coefficient of ``[y; u](k-1-d)`` in
   output ``i``'s equation; the current-sample coefficients ``L`` give ``H = (I - L)^-1``;
   ``A = A_o + K C``, ``C = H [0 I]`` (eqs 5-8 with the general ``H``; ``H = I`` for Table I).

5. **Uncertainty** (:mod:`.covariance`): the regression's sandwich covariance, carried to the
   model's free parameters by the delta method, stored as ``model.uncertainty``; for
   ``method="oe"`` the inverse Gauss-Newton information of the simulation error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ssme_envs.identification.alpha_fit import _binary_amplitudes, _Fit, _fit, _input_features
from ssme_envs.identification.arguments import check_arguments, real_record
from ssme_envs.identification.covariance import parameter_uncertainty
from ssme_envs.identification.feedthrough import check_feedthrough
from ssme_envs.identification.output_error import fit_output_error, held_out_criterion
from ssme_envs.identification.records import check_magnitudes
from ssme_envs.identification.structure import (
    DEFAULT_MAX_INDEX,
    DEFAULT_RANK_TOL,
    Candidate,
    StructureSearch,
    check_search_length,
    explore,
)
from ssme_envs.identification.structure import estimate_indices as structure_search
from ssme_envs.identification.structure_refined import refine_candidate, refine_contenders, walk_refined
from ssme_envs.identification.subspace_checks import check_input_directions, record_noise
from ssme_envs.models.statespace import AlphaCanonicalModel, AlphaStructure

# Share of the record the candidate structures are fitted on; the rest scores them.
ESTIMATION_SHARE = 2 / 3


@dataclass
class Identification:
    """An identified engine model with what produced it."""

    model: AlphaCanonicalModel
    search: StructureSearch | None
    intercept: np.ndarray
    method: str


def _names(names: Sequence[str] | None, count: int, prefix: str) -> tuple[str, ...]:
    return tuple(names) if names is not None else tuple(f"{prefix}{i}" for i in range(count))


def check_record(
    u: np.ndarray,
    y: np.ndarray,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate an input/output record; returns float arrays of shapes (T, m), (T, p).

    Raises
    ------
    ValueError
        Naming the problem: not real numbers (:func:`~ssme_envs.identification.arguments.real_record`:
        complex, bool, text, masked values), shapes, NaN/inf or values whose squares overflow
        (:func:`~ssme_envs.identification.records.check_magnitudes`), constant or linearly
        dependent signals.
    """
    # real numbers of the right shape first, for every identifier (DSR_e and the joint fit too)
    u = np.asarray(real_record(u, "u", "inputs"), dtype=float)
    y = np.asarray(real_record(y, "y", "outputs"), dtype=float)
    u = u[:, None] if u.ndim == 1 else u
    y = y[:, None] if y.ndim == 1 else y
    if u.ndim != 2 or y.ndim != 2:
        raise ValueError("inputs and outputs must be arrays of shape (samples, channels)")
    if u.shape[0] != y.shape[0]:
        raise ValueError(f"inputs have {u.shape[0]} samples but outputs have {y.shape[0]}")
    if u.shape[0] < 2:
        raise ValueError(f"the record has {u.shape[0]} samples: a record needs at least 2 to identify from")
    in_names = _names(input_names, u.shape[1], "u")
    out_names = _names(output_names, y.shape[1], "y")
    check_magnitudes(u, in_names, "input")
    check_magnitudes(y, out_names, "output")
    for arr, names, kind, what in (
        (u, in_names, "input", "does not excite the system"),
        (y, out_names, "output", "does not respond"),
    ):
        for j in range(arr.shape[1]):
            # relative to the channel's own size: a channel in tiny units is data, not a constant
            if np.ptp(arr[:, j]) <= 1e-12 * np.max(np.abs(arr[:, j])):
                raise ValueError(f"{kind} '{names[j]}' is constant: it {what}")
        centered = arr - arr.mean(axis=0)
        if arr.shape[1] > 1:
            s = np.linalg.svd(centered / np.linalg.norm(centered, axis=0), compute_uv=False)
            if s[-1] < 1e-8 * s[0]:
                raise ValueError(
                    f"the {kind}s {', '.join(names)} are linearly dependent (rank-deficient record)"
                )
    return u, y


def estimate_indices(
    u: np.ndarray,
    y: np.ndarray,
    max_index: int = DEFAULT_MAX_INDEX,
    rank_tol: float = DEFAULT_RANK_TOL,
    asymmetric: bool = True,
    output_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
) -> StructureSearch:
    """Observability indices by the row-by-row rank search (see :mod:`.structure`), without the
    choice among neighbours that :func:`identify` adds.

    Parameters
    ----------
    u, y : arrays, shapes (T, m), (T, p)
        Input and output record (deviations), already checked by :func:`check_record`.
    max_index, rank_tol : see :func:`ssme_envs.identification.structure.estimate_indices`.
    asymmetric : bool
        Allow for the piecewise-linear input gain of eq 36.
    output_names, input_names : sequences of str, optional
        Used in error messages.
    """
    # the record's length first (with the inputs alone, the fewest features): a short record is
    # the problem to name before what its inputs allow
    check_search_length(u.shape[0], y.shape[1], u.shape[1], max_index)
    gamma = _binary_amplitudes(u, input_names) if asymmetric else np.full(u.shape[1], np.nan)
    return structure_search(_input_features(u, gamma, asymmetric), y, max_index, rank_tol, output_names)


def check_gains(model: AlphaCanonicalModel, binary: np.ndarray, input_names: Sequence[str]) -> None:
    """Refuse an identified lambda outside (0, 2), where one side's valve gain changes sign (the
    model files refuse it too), saying why it can come out there: for a two-level input
    (``binary``) lambda is read from the outputs' means (eq 42), which an output offset moves."""
    outside = model.gains_outside_range()
    if not outside.size:
        return
    j = int(outside[0])
    radius = model.spectral_radius()
    if radius >= 1.0:  # the outputs' means drift with the unstable mode: not an offset's doing
        why = (
            f"the identified model is unstable (spectral radius {radius:.4g}): on an open-loop record "
            "of an unstable plant the outputs drift, and lambda with them; identify without the "
            "asymmetric gains (--symmetric), or from a record taken in closed loop"
        )
    elif binary[j]:
        why = (
            "a two-level input's lambda is read from the outputs' means (eq 42), so outputs measured "
            "with an offset from the operating point move it: subtract each output's operating-point "
            "value, or identify without the asymmetric gains (--symmetric)"
        )
    else:
        why = "identify without the asymmetric gains (--symmetric), or check the input's operating point"
    raise ValueError(
        f"input '{input_names[j]}': the identified lambda is {model.lam[j]:.4g}, outside (0, 2), where "
        f"the valve gain on one side of the operating point changes sign: {why}"
    )


def identify(
    u: np.ndarray,
    y: np.ndarray,
    dt: float,
    indices: Sequence[int] | None = None,
    method: str = "iv",
    asymmetric: bool = True,
    max_index: int = DEFAULT_MAX_INDEX,
    rank_tol: float = DEFAULT_RANK_TOL,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
    uncertainty: bool = True,
) -> Identification:
    """Identify an alpha-canonical model with asymmetric input gains from one record.

    Parameters
    ----------
    u, y : arrays, shapes (T, m), (T, p)
        Inputs and outputs as deviations from the operating point, one row per sample: real
        numbers (integers are read as floats), at least one column each, no masked values.
    dt : float
        Sample time, s.
    indices : sequence of int, optional
        Observability indices, ``p`` positive integers. When omitted, the rank search
        (:func:`estimate_indices`) proposes its index set and the sets one decision away, a walk
        over single indices goes on from the best, and the one with the lowest held-out BIC of its
        simulation error is kept, close contenders compared after output-error refinement
        (:mod:`.structure_refined`; ``result.search`` holds every candidate and the margin).
    method : {"iv", "ls", "oe"}
        "ls" is eq 27 as in the paper; "iv" adds two instrumental-variable passes, each kept only
        if it simulates the record better; "oe" starts from "iv" and minimizes the simulation
        error (output error): under white output noise its intervals hold where "iv" kept the
        biased least-squares estimate (``model.uncertainty.method`` says which was kept). It
        needs a stable estimate to start from.
    asymmetric : bool
        Estimate the lambda gains of eq 36 (otherwise lambda = 1).
    max_index, rank_tol : int >= 1, float in (0, 1)
        See :func:`estimate_indices`. ``max_index`` bounds the rank search; the walk over
        neighbouring sets may go past it, to at most ``MAX_WALK_ORDER`` (12) states in all,
        where the held-out scores say so (``indices=`` fixes the structure).
    input_names, output_names : sequences of str, optional
        ``m`` and ``p`` distinct names, carried into the model and used in error messages.
    uncertainty : bool
        Attach the covariance of the free parameters (``model.uncertainty``).

    Returns
    -------
    Identification

    Raises
    ------
    TypeError, ValueError
        Before any work, for an argument of the wrong kind or out of range, naming it
        (:func:`~ssme_envs.identification.arguments.check_arguments`; its TypeErrors are
        ValueErrors too), or a record too short for the indices or the structure search; then
        for a record :func:`check_record` refuses, one whose inputs are so nearly collinear that
        the gain along some input direction is not determined at its noise
        (:func:`~ssme_envs.identification.subspace_checks.check_input_directions`, as in DSR_e),
        one the fit cannot determine, or one whose outputs respond to the inputs within the sample
        (direct feedthrough, which the strictly proper form cannot hold: :mod:`.feedthrough`).
    """
    args = check_arguments(
        u,
        y,
        dt,
        indices=indices,
        method=method,
        asymmetric=asymmetric,
        max_index=max_index,
        rank_tol=rank_tol,
        input_names=input_names,
        output_names=output_names,
        uncertainty=uncertainty,
    )
    dt, indices, in_names, out_names = args.dt, args.indices, args.input_names, args.output_names
    u, y = check_record(args.u, args.y, in_names, out_names)
    names = (in_names, out_names)
    inputs = _names(in_names, u.shape[1], "u")  # the names the checks' messages give
    past = max(1, min(2 * max(indices or (max_index,)), u.shape[0] // (4 * (u.shape[1] + y.shape[1]))))
    check_input_directions(u, lambda: record_noise(u, y, past), inputs)

    search = None
    if indices is None:
        search = estimate_indices(u, y, max_index, rank_tol, asymmetric, out_names, in_names)
        # Candidates are fitted on the first part of the record and scored on the rest, where a
        # model that fitted the noise gains nothing; the chosen one is then fitted on it all.
        split = round(u.shape[0] * ESTIMATION_SHARE)
        head = (u[:split], y[:split])
        fits: dict[tuple[int, ...], _Fit] = {}

        def fit_head(indices: tuple[int, ...]) -> _Fit:
            if indices not in fits:
                fits[indices] = _fit(
                    AlphaStructure.from_indices(indices), *head, dt, method, asymmetric, names
                )
            return fits[indices]

        try:
            simulation = fit_head(search.candidates[0].indices).model.spectral_radius() < 1.0
        except ValueError as exc:  # too short to hold a part out: the rank rule decides alone
            search.candidates[0].note = f"no held-out comparison: {exc}"
        else:

            def score(indices: tuple[int, ...]) -> Candidate:
                cand = Candidate(indices, criterion=float("inf"))
                try:
                    fitted = fit_head(indices)
                except ValueError as exc:
                    cand.note = str(exc)
                    return cand
                cand.parameters = sum(theta.size for theta in fitted.thetas)
                cand.criterion, cand.rms_error = held_out_criterion(
                    fitted.model, cand.parameters, u, y, split, simulation
                )
                if not np.isfinite(cand.criterion):
                    cand.note = "the fitted model is unstable"
                return cand

            explore(search, score)
            if simulation:

                def refine_one(cand: Candidate) -> None:
                    refine_candidate(cand, fits[cand.indices].model, u, y, split)

                refine_contenders(search, refine_one)
                walk_refined(search, score, refine_one)
            kind = "simulation" if simulation else "one-step prediction"
            search.criterion = f"BIC of the {kind} error on the last {u.shape[0] - split} samples"
        fit = _fit(AlphaStructure.from_indices(search.indices), u, y, dt, method, asymmetric, names)
    else:
        fit = _fit(AlphaStructure.from_indices(indices), u, y, dt, method, asymmetric, names)
    # before the covariance and the output-error search: a feedthrough makes both meaningless
    check_feedthrough(fit.model, u, y, inputs, _names(out_names, y.shape[1], "y"))
    if search is not None:
        fit.model.fit["structure"] = search.to_dict()
    binary = ~np.isnan(fit.gamma)
    if method == "oe":
        model, intercept, cov = fit_output_error(
            fit.model, fit.intercept, u, y, asymmetric, binary, uncertainty
        )
        check_gains(model, binary, inputs)
        model.uncertainty = cov
        return Identification(model, search, intercept, method)
    check_gains(fit.model, binary, inputs)
    if uncertainty:
        fit.model.uncertainty = parameter_uncertainty(fit, y, method)
    return Identification(fit.model, search, fit.intercept, method)
