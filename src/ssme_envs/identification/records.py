"""Input/output records as CSV: a header row, a ``t`` column in seconds (or a given dt), columns by name."""

from __future__ import annotations

import csv
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ssme_envs.models.statespace import check_dt


def read_columns(
    path: str | Path, columns: Sequence[str], dt: float | None = None
) -> tuple[np.ndarray, float]:
    """Read the named columns of a CSV file and its sample time.

    The sample time comes from a ``t`` column (uniformly spaced, s) or from ``dt``; when both
    are there they must agree. The file is UTF-8; a byte-order mark at its start is skipped.

    Returns
    -------
    data : ndarray, shape (samples, len(columns))
    dt : float, s

    Raises
    ------
    ValueError
        For a missing file, a name that appears twice in the header, unknown or repeated columns,
        ragged rows, non-numeric cells, or an irregular or missing time base.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None
    rows = [r for r in rows if r and any(cell.strip() for cell in r)]
    if len(rows) < 2:
        raise ValueError(f"{path}: needs a header row and data rows")
    header = [h.strip() for h in rows[0]]
    repeated = [(name, n) for name, n in Counter(header).items() if n > 1]
    if repeated:
        name, n = repeated[0]
        times = "twice" if n == 2 else f"{n} times"
        raise ValueError(f"{path}: column '{name}' appears {times} in the header")
    if len(set(columns)) != len(columns):
        raise ValueError(f"{path}: a column is asked for twice: {', '.join(columns)}")
    unknown = [c for c in columns if c not in header]
    if unknown:
        raise ValueError(f"{path}: unknown column(s) {', '.join(unknown)}; the file has {', '.join(header)}")
    data = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {r} has {len(row)} fields, the header has {len(header)}")
        for c, cell in enumerate(row):
            try:
                data[r - 2, c] = float(cell)
            except ValueError:
                raise ValueError(
                    f"{path}: line {r}, column '{header[c]}': {cell!r} is not a number"
                ) from None
    index = {name: i for i, name in enumerate(header)}
    if "t" in index:
        t = data[:, index["t"]]
        steps = np.diff(t)
        if t.size < 2 or not np.all(np.isfinite(t)) or np.any(steps <= 0):
            raise ValueError(f"{path}: column 't' must increase strictly")
        step = float(np.median(steps))
        if np.max(np.abs(steps - step)) > 1e-6 * step + 1e-12:
            raise ValueError(
                f"{path}: column 't' is not uniformly spaced "
                f"(steps from {steps.min():g} to {steps.max():g} s)"
            )
        if dt is not None and abs(dt - step) > 1e-6 * step:
            raise ValueError(f"{path}: dt={dt:g} s disagrees with column 't' (step {step:g} s)")
        dt = step
    elif dt is None:
        raise ValueError(f"{path}: no 't' column; give the sample time (--dt)")
    return data[:, [index[c] for c in columns]], check_dt(dt)


def write_columns(path: str | Path, dt: float, names: Sequence[str], data: np.ndarray) -> None:
    """Write columns t, names... as CSV with full float precision."""
    t = np.arange(data.shape[0]) * dt
    header = ",".join(["t", *names])
    np.savetxt(path, np.column_stack([t, data]), delimiter=",", header=header, comments="", fmt="%.17g")


def check_validation_record(
    u: np.ndarray,
    y: np.ndarray,
    input_names: Sequence[str],
    output_names: Sequence[str],
    source: str | Path = "record",
) -> None:
    """Refuse a record on which SEE (sum err^2 / sum y^2) or NRMSE fit cannot be computed.

    ``u`` has shape (samples, inputs) and ``y`` (samples, outputs); ``source`` names the record
    (a file) in the messages. Refused: NaN or inf anywhere; a column whose squares, summed over
    the record, overflow float64 (|value| beyond about 1e154 / sqrt(samples)); an output that is
    zero throughout (or too small to square), for which SEE divides by zero; an output that never
    changes, for which the fit divides by zero.

    Raises
    ------
    ValueError
        ``"<source>: output 'pc' is zero throughout ..."`` and the like, one problem at a time.
    """
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    if u.ndim != 2 or y.ndim != 2 or u.shape[0] != y.shape[0]:
        raise ValueError(
            f"{source}: inputs {u.shape} and outputs {y.shape} must be (samples, channels) of equal length"
        )
    if len(input_names) != u.shape[1] or len(output_names) != y.shape[1]:
        raise ValueError(
            f"{source}: {len(input_names)} input and {len(output_names)} output names "
            f"for {u.shape[1]} input and {y.shape[1]} output columns"
        )
    if u.shape[0] == 0:
        raise ValueError(f"{source}: the record has no samples")
    # the error z - y may be up to twice the largest |y|: keep sum (2 y)^2 finite
    limit = 0.5 * np.sqrt(np.finfo(float).max / u.shape[0])
    for arr, names, kind in ((u, input_names, "input"), (y, output_names, "output")):
        for j, name in enumerate(names):
            col = arr[:, j]
            bad = ~np.isfinite(col)
            if bad.any():
                raise ValueError(
                    f"{source}: {kind} '{name}' has NaN or inf at sample {int(np.argmax(bad))} "
                    f"({int(bad.sum())} bad values)"
                )
            big = float(np.max(np.abs(col)))
            if big > limit:
                raise ValueError(
                    f"{source}: {kind} '{name}' reaches {big:.3g}: its squares overflow float64 "
                    f"(|values| must stay below {limit:.3g} over {u.shape[0]} samples)"
                )
    with np.errstate(under="ignore"):
        energy = np.sum(y**2, axis=0)
    for j, name in enumerate(output_names):
        if not energy[j] >= np.finfo(float).tiny:
            raise ValueError(
                f"{source}: output '{name}' is zero throughout (or too small to square): "
                "SEE = sum err^2 / sum y^2 is undefined"
            )
        if np.ptp(y[:, j]) == 0:
            raise ValueError(
                f"{source}: output '{name}' is constant ({y[0, j]:g}): the fit, "
                "100 (1 - |err| / |y - mean y|) %, is undefined"
            )


def record_labels(paths: Sequence[str | Path]) -> list[str]:
    """Distinct names for records, one per path: the file stem, then stem_2, stem_3, ... on a clash.

    Names are compared without regard to case, since they become file names (``<name>.png``)
    on file systems that may not tell case apart.
    """
    taken: set[str] = set()
    labels = []
    for path in paths:
        stem = Path(path).stem or "record"
        label, k = stem, 1
        while label.casefold() in taken:
            k += 1
            label = f"{stem}_{k}"
        taken.add(label.casefold())
        labels.append(label)
    return labels
