"""Input/output records as CSV: a header row, a ``t`` column in seconds (or a given dt), columns by name."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ssme_envs.models.statespace import check_dt


def read_columns(
    path: str | Path, columns: Sequence[str], dt: float | None = None
) -> tuple[np.ndarray, float]:
    """Read the named columns of a CSV file and its sample time.

    The sample time comes from a ``t`` column (uniformly spaced, s) or from ``dt``; when both
    are there they must agree.

    Returns
    -------
    data : ndarray, shape (samples, len(columns))
    dt : float, s

    Raises
    ------
    ValueError
        For a missing file, unknown or repeated columns, ragged rows, non-numeric cells, or an
        irregular or missing time base.
    """
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None
    rows = [r for r in rows if r and any(cell.strip() for cell in r)]
    if len(rows) < 2:
        raise ValueError(f"{path}: needs a header row and data rows")
    header = [h.strip() for h in rows[0]]
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
