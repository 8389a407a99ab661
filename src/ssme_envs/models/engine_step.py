"""The SSME engine step (valve backlash and stiction, the asymmetric gains, the alpha-canonical
dynamics) on Python floats for one engine and on arrays for N engines: the per-step core that the
env tasks call from their hot paths and the simulators of :mod:`ssme_envs.models.engine` build on.
Its forms sit side by side because they must stay one arithmetic, the same IEEE operations in the
same order, so that an engine gives the same bits alone or batched."""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ssme_envs.models.kernels import load_kernel

if TYPE_CHECKING:
    from ssme_envs.models.engine import TruthConfig
    from ssme_envs.models.statespace import AlphaCanonicalModel


@dataclass(frozen=True)
class StepParameters:
    """What one engine step needs: the alpha-canonical shift structure, K, B, lambda - 1 (arrays,
    with a leading batch axis when every engine has its own model), and the valve widths."""

    shift_source: tuple[int, ...]
    K: np.ndarray
    B: np.ndarray
    lam_minus_one: np.ndarray
    half_backlash: float
    stiction: float

    @classmethod
    def from_model(cls, model: AlphaCanonicalModel, config: TruthConfig) -> StepParameters:
        a_o = model.structure.shift_matrix()
        lam = model.lam - 1.0 if config.asymmetric_gains else np.zeros(model.n_inputs)
        return cls(
            shift_source=tuple(int(np.argmax(row)) if row.any() else -1 for row in a_o),
            # The last p states are w = H^-1 y; they enter through A's last columns, K H.
            K=model.A[:, model.A.shape[0] - model.n_outputs :].copy(),
            B=model.B.copy(),
            lam_minus_one=lam,
            half_backlash=0.5 * config.backlash,
            stiction=float(config.stiction),
        )

    def floats(self) -> tuple[list, list, list]:
        """K and B rows and lambda - 1 as Python floats, for :func:`step_floats`."""
        return self.K.tolist(), self.B.tolist(), self.lam_minus_one.tolist()


# The engine step exists twice, on purpose: on Python floats for one engine (an order of
# magnitude faster than numpy on 1-element arrays, for the scalar environment) and on arrays
# for a batch (the vector environment, the simulators). Both perform the same IEEE operations
# in the same order, so an engine gives the same bits alone or batched; tests hold them to it.
# Order: linkage = min(max(l, c - h), c + h); valve = q if |q - v| > s else v;
# u* = v + (lambda - 1)|v|; x_i <- (x_src(i) + sum_j K_ij y_j) + sum_j B_ij u*_j, sums left to right
# (no x_src term for the first state of each output's chain).


def valves_floats(linkage: list, valve: list, command: list, half: float, stick: float) -> tuple[list, list]:
    """Backlash then stiction for one engine's valves, on floats. Returns (linkage, valve)."""
    if half:
        linkage = [min(max(lk, c - half), c + half) for lk, c in zip(linkage, command)]
    else:
        linkage = command
    if stick:
        valve = [q if abs(q - v) > stick else v for q, v in zip(linkage, valve)]
    else:
        valve = linkage
    return linkage, valve


def dynamics_floats(x: list, u: list, shift_source: tuple, k_rows: list, b_rows: list) -> list:
    """``x(k+1) = A_o x + K y + B u`` (eq 9) for one engine on floats, ``y`` the last p states."""
    y = x[len(x) - len(k_rows[0]) :]
    if len(y) == 2 and len(u) == 2:  # the SSME's two outputs and two valves, unrolled, same order
        y0, y1 = y
        u0, u1 = u
        return [
            ((x[source] + (k0 * y0 + k1 * y1)) if source >= 0 else (k0 * y0 + k1 * y1)) + (b0 * u0 + b1 * u1)
            for source, (k0, k1), (b0, b1) in zip(shift_source, k_rows, b_rows)
        ]
    x_next = []
    for source, k_row, b_row in zip(shift_source, k_rows, b_rows):
        ky = k_row[0] * y[0]
        for k, yj in zip(k_row[1:], y[1:]):
            ky = ky + k * yj
        bu = b_row[0] * u[0]
        for b, uj in zip(b_row[1:], u[1:]):
            bu = bu + b * uj
        x_next.append(((x[source] + ky) if source >= 0 else ky) + bu)
    return x_next


def step_floats(x: list, linkage: list, valve: list, command: list, p: StepParameters, rows: tuple) -> tuple:
    """One engine, one sample, on floats; ``rows`` = ``p.floats()``. Returns (x, linkage, valve)."""
    k_rows, b_rows, lam = rows
    linkage, valve = valves_floats(linkage, valve, command, p.half_backlash, p.stiction)
    u = [v + g * abs(v) for v, g in zip(valve, lam)]
    return dynamics_floats(x, u, p.shift_source, k_rows, b_rows), linkage, valve


# The env tasks' engines have two valves and two outputs: their float step is the one above,
# unrolled over unpacked floats (a third of its time, which is list building and zips), the
# same operations in the same order.


def pair_rows(shift_source: tuple, k_rows: list, b_rows: list) -> tuple:
    """Per state ``(source, K_i0, K_i1, B_i0, B_i1)`` of a two-output, two-valve model, for
    :func:`dynamics_pair_floats`."""
    return tuple(
        (source, k0, k1, b0, b1)
        for source, (k0, k1), (b0, b1) in zip(shift_source, k_rows, b_rows, strict=True)
    )


def valves_pair_floats(
    linkage: tuple, valve: tuple, c0: float, c1: float, half: float, stick: float
) -> tuple[tuple, tuple]:
    """:func:`valves_floats` for two valves. ``min(max(l, lo), hi)`` is spelled as the builtins
    decide (each returns its first argument unless the second lies strictly beyond it), which
    gives the same value, NaN and signed zeros included, without two calls per valve."""
    l0, l1 = linkage
    if half:
        lo, hi = c0 - half, c0 + half
        l0 = lo if lo > l0 else l0
        l0 = hi if hi < l0 else l0
        lo, hi = c1 - half, c1 + half
        l1 = lo if lo > l1 else l1
        l1 = hi if hi < l1 else l1
    else:
        l0, l1 = c0, c1
    if stick:
        v0, v1 = valve
        v0 = l0 if abs(l0 - v0) > stick else v0
        v1 = l1 if abs(l1 - v1) > stick else v1
    else:
        v0, v1 = l0, l1
    return (l0, l1), (v0, v1)


def dynamics_pair_floats(x: list, u0: float, u1: float, rows: tuple) -> list:
    """:func:`dynamics_floats` for two outputs and two valves; ``rows`` from :func:`pair_rows`."""
    y0, y1 = x[-2], x[-1]
    return [
        ((x[source] + (k0 * y0 + k1 * y1)) if source >= 0 else (k0 * y0 + k1 * y1)) + (b0 * u0 + b1 * u1)
        for source, k0, k1, b0, b1 in rows
    ]


def dynamics_pair_offset_floats(x: list, u0: float, u1: float, rows: tuple) -> list:
    """:func:`dynamics_pair_floats` plus a constant per state, added last (the linked model's
    operating-point offset): ``rows`` hold ``(source, K_i0, K_i1, B_i0, B_i1, offset_i)``. One
    pass instead of a second list for the sum; the same operations in the same order."""
    y0, y1 = x[-2], x[-1]
    return [
        (((x[source] + (k0 * y0 + k1 * y1)) if source >= 0 else (k0 * y0 + k1 * y1)) + (b0 * u0 + b1 * u1))
        + offset
        for source, k0, k1, b0, b1, offset in rows
    ]


def valves_arrays(linkage: np.ndarray, valve: np.ndarray, command: np.ndarray, half: float, stick: float):
    """Backlash then stiction for N engines' valves, (m, N) arrays. Returns (linkage, valve)."""
    linkage = np.minimum(np.maximum(linkage, command - half), command + half) if half else command
    valve = np.where(np.abs(linkage - valve) > stick, linkage, valve) if stick else linkage
    return linkage, valve


def dynamics_arrays(
    x: np.ndarray, u: np.ndarray, shift_source: tuple, k_gain: np.ndarray, b_gain: np.ndarray
):
    """``x(k+1) = A_o x + K y + B u`` for N engines, state-major x (n, N), u (m, N); K (n, p) and
    B (n, m), or (n, p, N) and (n, m, N) for one model per engine."""
    n_out = k_gain.shape[1]
    y = x[x.shape[0] - n_out :]
    scratch = np.empty((x.shape[0], x.shape[1]))
    x_next = np.multiply(_column(k_gain, 0), y[0])
    for j in range(1, n_out):
        x_next += np.multiply(_column(k_gain, j), y[j], out=scratch)
    for i, source in enumerate(shift_source):  # the shift part of A_o: x_i += x_src(i)
        if source >= 0:
            x_next[i] += x[source]
    bu = np.multiply(_column(b_gain, 0), u[0])
    for j in range(1, b_gain.shape[1]):
        bu += np.multiply(_column(b_gain, j), u[j], out=scratch)
    x_next += bu
    return x_next


def step_arrays(
    x: np.ndarray, linkage: np.ndarray, valve: np.ndarray, command: np.ndarray, p: StepParameters
):
    """N engines, one sample, state-major: x (n, N), linkage, valve, command (m, N). Returns
    (x, linkage, valve). Rows are contiguous, so every operation runs over N engines at once."""
    linkage, valve = valves_arrays(linkage, valve, command, p.half_backlash, p.stiction)
    lam = p.lam_minus_one
    u = valve + (lam[:, None] if lam.ndim == 1 else lam) * np.abs(valve)
    return dynamics_arrays(x, u, p.shift_source, p.K, p.B), linkage, valve


def _column(gain: np.ndarray, j: int) -> np.ndarray:
    """Column j of a gain as (n, 1) to multiply a row of N engines, or (n, N) when per engine."""
    return gain[:, j, None] if gain.ndim == 2 else gain[:, j]


# The two-valve float step compiled (_engine_kernel.c): pair_step(x, linkage, valve, c0, c1, n0,
# n1, half, stick, table, width, step) -> (x, linkage, valve) runs valves_pair_floats, the gains
# u* = v + (lambda - 1)|v - n| and dynamics_pair_floats (width 5) or dynamics_pair_offset_floats
# (width 6) on one step's rows of a packed table, in the reference's operations and order.


def pair_table(steps: Iterable[tuple[Sequence[float], tuple]]) -> tuple[bytes, int]:
    """The kernel's packed float64 table of (lambda - 1 of both valves, per-state rows of
    :func:`pair_rows`, with each state's offset last for the linked model) per step, and its
    width (5, or 6 with offsets)."""
    flat: list[float] = []
    widths = set()
    for lam, rows in steps:
        flat += lam
        for row in rows:
            flat += row
            widths.add(len(row))
    (width,) = widths
    return np.array(flat, dtype=np.float64).tobytes(), width


def pair_step_reference(
    x: list, linkage: tuple, valve: tuple, c0: float, c1: float, n0: float, n1: float,
    half: float, stick: float, lam: Sequence[float], rows: tuple,
) -> tuple[list, tuple, tuple]:  # fmt: skip
    """What the kernel's ``pair_step`` computes, on the Python floats: the reference it is
    checked against."""
    linkage, (v0, v1) = valves_pair_floats(linkage, valve, c0, c1, half, stick)
    u0, u1 = v0 + lam[0] * abs(v0 - n0), v1 + lam[1] * abs(v1 - n1)
    dynamics = dynamics_pair_offset_floats if len(rows[0]) == 6 else dynamics_pair_floats
    return dynamics(x, u0, u1, rows), linkage, (v0, v1)


# The batch kernels (plant_batch, task_batch: N engines state-major, stepped in place) take the
# task's numbers as one float64 array, these entries in this order (_engine_arithmetic.h's enum).
BATCH_CONFIG = (
    "scale", "s0", "s1", "dt", "limit", "error_weight", "rate_weight", "envelope", "cost_bound", "horizon",
    "fault_kind", "fault_index", "magnitude", "fault_step", "half", "stick", "width", "scheduled",
)  # fmt: skip


# the batch kernels' fault codes (its fault_kind entry; _engine_arithmetic.h's enum)
FAULT_CODES = {None: 0, "stuck_valve": 1, "gain_loss": 2, "sensor_bias": 3}


def has_batch(kernel: Any) -> bool:
    """Whether a kernel has the batch forms (a build without them steps batches with numpy)."""
    return hasattr(kernel, "plant_batch") and hasattr(kernel, "task_batch")


def batch_config(**entries: float) -> np.ndarray:
    """The batch kernels' config from its named entries (:data:`BATCH_CONFIG`; those not given
    are 0)."""
    unknown = sorted(set(entries) - set(BATCH_CONFIG))
    if unknown:
        raise ValueError(f"unknown batch config entries {unknown}")
    return np.array([float(entries.get(name, 0.0)) for name in BATCH_CONFIG])


def _batch_agrees(kernel: Any, x: list, lam: tuple, rows: tuple, table: bytes, width: int, k: int,
                  commands: list, half: float, stick: float) -> bool:  # fmt: skip
    """Whether ``plant_batch`` on the envs of ``commands`` (state ``x`` each, step 1 of the table,
    the gains about step 1's nominal valves) and ``task_batch``'s plant give the reference's bits."""
    n = len(commands)
    nominal = (0.1 * k, -0.2 * k)
    config = batch_config(half=half, stick=stick, width=width, scheduled=1, scale=1.0)
    offsets = np.array([[0.0, 0.0], nominal])
    x_rows = np.array([x] * n).T.copy()
    linkage, valve = np.array([[0.01] * n, [-0.0] * n]), np.array([[-0.02] * n, [0.004] * n])
    command, t = np.array(commands).T.copy(), np.full(n, 2, dtype=np.int64)
    plant = (x_rows.copy(), linkage.copy(), valve.copy())
    kernel.plant_batch(*plant, command, t, config, table, offsets)
    # task_batch's plant, its commands the nominal valves plus these actions (scale 1)
    task_x, task_link, task_valve = x_rows.copy(), linkage.copy(), valve.copy()
    zeros, floats = np.zeros(n), np.zeros(n, dtype=np.float32)
    kernel.task_batch(task_x, task_link, task_valve, zeros.copy(), zeros.copy(), zeros.copy(), zeros, zeros,
                      command, t, zeros, zeros, floats, floats, np.empty((10, n), dtype=np.float32),
                      np.empty(n), np.empty(n, dtype=bool), config, table, offsets)  # fmt: skip
    fixed = (x, (0.01, -0.0), (-0.02, 0.004))
    for j, (c0, c1) in enumerate(commands):
        want = pair_step_reference(*fixed, c0, c1, *nominal, half, stick, lam, rows)
        got = (plant[0][:, j].tolist(), tuple(plant[1][:, j].tolist()), tuple(plant[2][:, j].tolist()))
        moved = (nominal[0] + c0, nominal[1] + c1)
        task_want = pair_step_reference(*fixed, *moved, *nominal, half, stick, lam, rows)
        task_got = (task_x[:, j].tolist(), tuple(task_link[:, j].tolist()), tuple(task_valve[:, j].tolist()))
        if not (_same_bits(got, want) and _same_bits(task_got, task_want)):
            return False
    return True


def _kernel_agrees(kernel: Any) -> bool:
    """Whether ``kernel.pair_step`` and its batch forms give :func:`pair_step_reference`'s bits
    on a check set: both widths, backlash and stiction on and off, signed zeros, NaN and inf."""
    special = [0.0, -0.0, 1e-300, -3.5e-3, 0.02, math.inf, math.nan]
    states = [[0.3, -0.0, 1.5e-3, -0.7], [math.nan, 2.0, -0.0, 1e300], [0.0, 0.0, -2.5e-3, 0.011]]
    rows = ((-1, 0.31, -0.2, 0.05, 1e-3), (0, -0.4, 0.9, -0.0, 0.2), (-1, 1.7, 0.25, 0.3, -0.6),
            (2, 0.05, -0.8, 2.0, 0.01))  # fmt: skip
    lam = (0.125, -0.3)
    dead_bands = ((0.0, 0.0), (1e-3, 0.0), (0.0, 2e-3), (1e-3, 2e-3))  # half backlash, stiction: off, on
    for width in (5, 6):
        table_rows = rows if width == 5 else tuple((*row, 0.25 * i - 0.5) for i, row in enumerate(rows))
        table, _ = pair_table([((0.0, 0.0), table_rows), (lam, table_rows)])
        for k, x in enumerate(states):
            for c0, c1 in zip(special, special[::-1]):
                for half, stick in dead_bands:
                    args = (x, (0.01, -0.0), (-0.02, 0.004), c0, c1, 0.1 * k, -0.2 * k, half, stick)
                    got = kernel.pair_step(*args, table, width, 1)
                    want = pair_step_reference(*args, lam, table_rows)
                    if not _same_bits(got, want):
                        return False
            commands = list(zip(special, special[::-1]))  # every pair above, one env each
            for half, stick in dead_bands:
                batch = (x, lam, table_rows, table, width, k, commands, half, stick)
                if has_batch(kernel) and not _batch_agrees(kernel, *batch):
                    return False
    return True


def _same_bits(a: Any, b: Any) -> bool:
    """Whether two (x, linkage, valve) hold the same floats bit for bit (-0.0 apart from 0.0),
    any NaN equal to any NaN (a NaN's payload is not part of the arithmetic's contract)."""
    flat_a, flat_b = ([*x, *linkage, *valve] for x, linkage, valve in (a, b))
    return len(flat_a) == len(flat_b) and all(
        (p != p and q != q) or struct.pack("<d", p) == struct.pack("<d", q)
        for p, q in zip(flat_a, flat_b, strict=True)
    )


_KERNEL = load_kernel("_engine_kernel", _kernel_agrees, "engine")  # the module, or None: the reference
KERNEL = "python" if _KERNEL is None else "compiled"  # which arithmetic the tasks' float step runs


def kernel() -> Any:
    """The compiled kernel module the package runs, None where it runs the Python reference
    (not built, turned off by ``SSME_ENVS_NO_KERNEL``, or not giving the reference's bits)."""
    return _KERNEL
