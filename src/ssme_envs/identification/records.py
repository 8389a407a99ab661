"""Input/output records as CSV: a header row, a ``t`` column in seconds (or a given dt), columns by name."""

from __future__ import annotations

import csv
import io
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ssme_envs.input_files import FileTooLarge, NotRegularFile, read_bounded
from ssme_envs.models.statespace import check_dt

# Generous for any test record (a million rows of ten columns is about 200 MB); it stops a file that
# would only end in an out-of-memory failure long after it was named.
MAX_CSV_BYTES = 1 << 30
# A record sampled less often than daily holds no engine or nozzle dynamics, and a longer step
# drives the time axes of the report's figures towards overflow (--dt 1e300 did).
MAX_DT = 86_400.0
# A step under a nanosecond is no test rig's, and it drives the figures' time axes to zero width
# (--dt 1e-300 wrote a model no env takes; 1e-320 failed inside the plotting).
MIN_DT = 1e-9
# Relative distance within which a record's step is taken as the shorter decimal (0.04)
SNAP_TOLERANCE = 1e-10
# A time stamp is only known to the float resolution of its magnitude (2.4e-7 s at epoch-style
# times near 1.7e9 s): uniform steps below a hundred times that cannot be told from irregular ones.
MIN_STEP_RESOLUTIONS = 100


def read_text(path: Path, max_bytes: int = MAX_CSV_BYTES) -> str:
    """The UTF-8 text of a regular file (a byte-order mark at its start skipped).

    Raises
    ------
    ValueError
        For a missing file; anything but a regular file after symlinks are followed (a FIFO
        blocks its reader, a device such as /dev/zero never ends); a file over ``max_bytes``;
        text that is not UTF-8.
    """
    try:
        return read_bounded(path, max_bytes).decode("utf-8-sig")
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except NotRegularFile as exc:
        raise ValueError(f"{path}: cannot read: not a regular file ({exc.kind})") from None
    except FileTooLarge:
        raise ValueError(
            f"{path}: larger than {max_bytes / 2**30:.3g} GiB, the most a record may have"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None


def _number(cell: str) -> float:
    """A CSV cell as a float; ValueError for anything but a number as CSV writes them."""
    if "_" in cell:  # float() reads 1_0 as 10, a Python literal, not a number in a CSV
        raise ValueError(cell)
    return float(cell)


def _sample_time(path: Path, t: np.ndarray, dt: float | None) -> float:
    """The step of a uniformly spaced time column (s), checked against a given ``dt``."""
    steps = np.diff(t)
    if t.size < 2:
        raise ValueError(f"{path}: the record has {t.size} sample(s): a sample time needs two")
    if not np.all(np.isfinite(t)) or np.any(steps <= 0):
        raise ValueError(f"{path}: column 't' must increase strictly")
    step = float(np.median(steps))
    # each stamp is rounded to the spacing of floats at its magnitude: a step is known to two of them
    resolution = float(np.spacing(np.max(np.abs(t))))
    if resolution * MIN_STEP_RESOLUTIONS > step:
        raise ValueError(
            f"{path}: column 't' cannot resolve its steps of {step:g} s: near {np.max(np.abs(t)):g} s a "
            f"float keeps only {resolution:g} s (subtract the start time)"
        )
    if np.max(np.abs(steps - step)) > 1e-6 * step + 2 * resolution:
        raise ValueError(
            f"{path}: column 't' is not uniformly spaced (steps from {steps.min():g} to {steps.max():g} s)"
        )
    # the least-squares slope averages the stamps' rounding out, where the median step keeps it
    k = np.arange(t.size) - (t.size - 1) / 2
    slope = float(np.dot(k, t - t[0]) / np.dot(k, k))
    if dt is not None and abs(dt - slope) > 1e-6 * slope:
        raise ValueError(f"{path}: dt={dt:g} s disagrees with column 't' (step {slope:g} s)")
    return _shortest_decimal(slope, SNAP_TOLERANCE * slope)


def _shortest_decimal(value: float, tolerance: float) -> float:
    """The decimal of fewest significant digits within ``tolerance`` of ``value``: stamps written
    as ``i * 0.04`` give steps of 0.04 up to their rounding (0.040000000000000036 as the median),
    and the sample time the data were taken at is 0.04, which the envs' plants are then equal to."""
    for digits in range(1, 18):
        rounded = float(f"{value:.{digits}g}")
        if abs(rounded - value) <= tolerance:
            return rounded
    return value


def read_columns(
    path: str | Path, columns: Sequence[str], dt: float | None = None
) -> tuple[np.ndarray, float]:
    """Read the named columns of a CSV file and its sample time.

    The sample time comes from a ``t`` column (uniformly spaced, s) or from ``dt``; when both
    are there they must agree. The file is UTF-8; a byte-order mark at its start is skipped.
    Only the named columns and ``t`` must hold numbers; other columns (a note, the empty one a
    trailing comma makes) are left unread.

    Returns
    -------
    data : ndarray, shape (samples, len(columns))
    dt : float, s

    Raises
    ------
    ValueError
        For a missing file or one that is not a regular file or is over ``MAX_CSV_BYTES``, a
        name that appears twice in the header, unknown or repeated columns, ragged rows,
        non-numeric cells in the columns read, or an irregular or missing time base, or a sample
        time over ``MAX_DT``.
    """
    path = Path(path)
    rows = list(csv.reader(io.StringIO(read_text(path), newline="")))
    rows = [r for r in rows if r and any(cell.strip() for cell in r)]
    if len(rows) < 2:
        raise ValueError(f"{path}: needs a header row and data rows")
    header = [h.strip() for h in rows[0]]
    # unnamed columns (trailing commas) cannot be asked for: repeats of them are harmless
    repeated = [(name, n) for name, n in Counter(header).items() if n > 1 and name]
    if repeated:
        name, n = repeated[0]
        times = "twice" if n == 2 else f"{n} times"
        raise ValueError(f"{path}: column '{name}' appears {times} in the header")
    if len(set(columns)) != len(columns):
        raise ValueError(f"{path}: a column is asked for twice: {', '.join(columns)}")
    unknown = [c for c in columns if not c or c not in header]
    if unknown:
        raise ValueError(f"{path}: unknown column(s) {', '.join(unknown)}; the file has {', '.join(header)}")
    index = {name: i for i, name in enumerate(header)}
    read = [*columns, *(["t"] if "t" in index and "t" not in columns else [])]
    data = np.empty((len(rows) - 1, len(read)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {r} has {len(row)} fields, the header has {len(header)}")
        for c, name in enumerate(read):
            cell = row[index[name]]
            try:
                data[r - 2, c] = _number(cell)
            except ValueError:
                raise ValueError(f"{path}: line {r}, column '{name}': {cell!r} is not a number") from None
    if "t" in index:
        dt = _sample_time(path, data[:, read.index("t")], dt)
    elif dt is None:
        raise ValueError(f"{path}: no 't' column; give the sample time (--dt)")
    dt = check_dt(dt)
    if dt > MAX_DT:
        raise ValueError(f"{path}: sample time {dt:g} s is over a day ({MAX_DT:g} s): no dynamics to follow")
    if dt < MIN_DT:
        raise ValueError(f"{path}: sample time {dt:g} s is under a nanosecond ({MIN_DT:g} s)")
    return data[:, : len(columns)], dt


def write_columns(path: str | Path, dt: float, names: Sequence[str], data: np.ndarray) -> None:
    """Write columns t, names... as CSV with full float precision."""
    t = np.arange(data.shape[0]) * dt
    header = ",".join(["t", *names])
    np.savetxt(path, np.column_stack([t, data]), delimiter=",", header=header, comments="", fmt="%.17g")


def check_magnitudes(arr: np.ndarray, names: Sequence[str], kind: str, source: str | Path = "record") -> None:
    """Refuse NaN or inf in the columns of ``arr`` (samples, channels), and values whose squares,
    summed over the record, overflow float64: ``|value|`` beyond ``0.5 sqrt(max float / samples)``
    (about 1e154 / sqrt(samples)). ``kind`` (input, output) and ``names`` name the column.

    Raises
    ------
    ValueError
        ``"<source>: input 'tau' reaches 1.7e+158: its squares overflow float64 ..."`` and the like.
    """
    # an error z - y may be up to twice the largest |y|: keep sum (2 y)^2 finite
    limit = 0.5 * np.sqrt(np.finfo(float).max / max(arr.shape[0], 1))
    for j, name in enumerate(names):
        col = arr[:, j]
        bad = ~np.isfinite(col)
        if bad.any():
            raise ValueError(
                f"{source}: {kind} '{name}' has NaN or inf at sample {int(np.argmax(bad))} "
                f"({int(bad.sum())} bad values)"
            )
        big = float(np.max(np.abs(col))) if col.size else 0.0
        if big > limit:
            raise ValueError(
                f"{source}: {kind} '{name}' reaches {big:.3g}: its squares overflow float64 "
                f"(|values| must stay below {limit:.3g} over {arr.shape[0]} samples)"
            )


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
    check_magnitudes(u, input_names, "input", source)
    check_magnitudes(y, output_names, "output", source)
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
