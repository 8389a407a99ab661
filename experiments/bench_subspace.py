"""DSR_e against a peer subspace method (SIPPY's N4SID, else nfoursid) on the same records.

For a few seeded 3rd-order, 2-input, 2-output systems (one real pole and a complex pair,
random magnitudes 0.5-0.95) with process noise ``w`` on every state and white measurement
noise ``v`` (``x+ = A x + B u + w``, ``y = C x + v``; std of ``v`` 10 % of each output's
noise-free std, of ``w`` 0.2 with unit binary inputs), identify from N = 5000 samples and report
per method: the order found, the NRMSE fit % of the pure simulation on a fresh noise-free
record (worst output), the worst relative pole error % after matching poles one to one, and
the wall time (median of the repeats, after one warm-up call) with the ratio DSR_e / peer.
Both methods choose the order themselves (DSR_e: BIC of its one-step prediction errors; SIPPY:
its default threshold).
Writes the table to experiments/results/bench_subspace.md as well.

The peer is not a dependency of the package. Install it into the same environment with

    python -m pip install sippy-unipi      # preferred peer (N4SID)
    python -m pip install nfoursid         # fallback

Timings depend on BLAS threading; on a shared machine pin it:

    OPENBLAS_NUM_THREADS=1 python experiments/bench_subspace.py [--repeats 5] [--systems 4]
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from ssme_envs.identification.metrics import fit_percent
from ssme_envs.identification.subspace import InnovationsModel, dsr_e
from ssme_envs.outputs import write_text
from ssme_envs.script_options import int_within, script_parser

OUT = Path(__file__).resolve().parent / "results" / "bench_subspace.md"
SAMPLES = 5000
DT = 0.04
INSTALL_HINT = (
    "no peer subspace package found: install one into this environment with "
    "`python -m pip install sippy-unipi` (or `python -m pip install nfoursid`)"
)

Fitted = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # A, B, C, D


def random_system(seed: int) -> Fitted:
    """A stable 3rd-order, 2-input, 2-output system with one real pole and a complex pair."""
    rng = np.random.default_rng(seed)
    real = rng.uniform(0.5, 0.95)
    radius, angle = rng.uniform(0.5, 0.95), rng.uniform(0.2, 1.2)
    modal = np.array(
        [
            [real, 0.0, 0.0],
            [0.0, radius * np.cos(angle), radius * np.sin(angle)],
            [0.0, -radius * np.sin(angle), radius * np.cos(angle)],
        ]
    )
    basis = rng.standard_normal((3, 3)) + 2 * np.eye(3)
    a = basis @ modal @ np.linalg.inv(basis)
    return a, rng.standard_normal((3, 2)), rng.standard_normal((2, 3)), np.zeros((2, 2))


def simulate_truth(system: Fitted, u: np.ndarray, w: np.ndarray | None, v: np.ndarray | None) -> np.ndarray:
    a, b, c, d = system
    x = np.zeros(a.shape[0])
    y = np.empty((u.shape[0], c.shape[0]))
    for k in range(u.shape[0]):
        y[k] = c @ x + d @ u[k] + (0.0 if v is None else v[k])
        x = a @ x + b @ u[k] + (0.0 if w is None else w[k])
    return y


def records(seed: int) -> tuple[Fitted, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(system, u, y) for identification and (u_val, y_val) noise-free for validation."""
    system = random_system(seed)
    rng = np.random.default_rng(1000 + seed)
    u = np.sign(rng.standard_normal((SAMPLES, 2)))
    clean = simulate_truth(system, u, None, None)
    w = 0.2 * rng.standard_normal((SAMPLES, 3))
    v = 0.1 * clean.std(axis=0) * rng.standard_normal((SAMPLES, 2))
    y = simulate_truth(system, u, w, v)
    u_val = np.sign(rng.standard_normal((SAMPLES, 2)))
    return system, u, y, u_val, simulate_truth(system, u_val, None, None)


def fit_dsr_e(u: np.ndarray, y: np.ndarray) -> Fitted:
    model = dsr_e(u, y, DT).model
    return model.A, model.B, model.C, model.D


def load_peer() -> tuple[str, Callable[[np.ndarray, np.ndarray], Fitted]]:
    """The peer's name and a fit function, imported lazily."""
    try:
        from sippy_unipi import system_identification
    except ImportError:
        pass
    else:

        def fit_sippy(u: np.ndarray, y: np.ndarray) -> Fitted:
            model = system_identification(y.T, u.T, "N4SID", tsample=DT)
            return np.asarray(model.A), np.asarray(model.B), np.asarray(model.C), np.asarray(model.D)

        return "SIPPY N4SID", fit_sippy
    try:
        import pandas as pd
        from nfoursid.nfoursid import NFourSID
    except ImportError:
        sys.exit(INSTALL_HINT)

    def fit_nfoursid(u: np.ndarray, y: np.ndarray) -> Fitted:
        names_u, names_y = [f"u{i}" for i in range(u.shape[1])], [f"y{i}" for i in range(y.shape[1])]
        frame = pd.DataFrame(np.hstack([u, y]), columns=names_u + names_y)
        ident = NFourSID(frame, output_columns=names_y, input_columns=names_u, num_block_rows=10)
        ident.subspace_identification()
        # nfoursid has no automatic order: use the largest gap of its singular values, as DSR_e does
        s = np.diagonal(ident.R32_decomposition.eigenvalues)  # stored as a diagonal matrix
        gaps = np.log10(s[:-1] / s[1:])
        model, _ = ident.system_identification(rank=int(np.argmax(gaps[:10])) + 1)
        return model.a, model.b, model.c, model.d

    return "nfoursid", fit_nfoursid


def worst_pole_error(true: np.ndarray, found: np.ndarray) -> float:
    """Largest |found - true| / |true| after matching (extra or missing poles unmatched: inf)."""
    if true.size != found.size:
        return float("inf")
    cost = np.abs(true[:, None] - found[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(np.max(cost[rows, cols] / np.abs(true[rows])))


def median_time(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm-up: imports and first-call caches
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def evaluate(fit: Fitted, system: Fitted, u_val: np.ndarray, y_val: np.ndarray) -> tuple[int, float, float]:
    a, b, c, d = fit
    model = InnovationsModel(a, b, c, d, np.zeros((a.shape[0], c.shape[0])), DT)
    fit_pct = float(np.min(fit_percent(y_val, model.simulate(u_val))))
    err = worst_pole_error(np.linalg.eigvals(system[0]), model.poles())
    return a.shape[0], fit_pct, 100.0 * err


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int_within(1), default=5)
    parser.add_argument("--systems", type=int_within(1), default=4)
    args = parser.parse_args()
    peer_name, fit_peer = load_peer()
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    command = "python experiments/bench_subspace.py" + "".join(
        f" --{k} {v}" for k, v in (("repeats", args.repeats), ("systems", args.systems))
    )
    lines = [
        "# DSR_e against a peer subspace method",
        "",
        f"Command: `OPENBLAS_NUM_THREADS={threads} {command}`. Peer: {peer_name}.",
        "",
        f"3rd-order, 2-input, 2-output systems (seeds 1..{args.systems}), N = {SAMPLES}, binary random "
        "inputs, process noise on every state (std 0.2) and measurement noise (10 % of each output's "
        "std). Fit: NRMSE % of the pure simulation on a fresh noise-free record, worst output. Pole "
        f"error: worst relative error after matching, %. Time: median of {args.repeats} after a warm-up.",
        "",
        f"| seed | true poles | method | order | fit % | pole error % | time ms | time / {peer_name} |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for seed in range(1, args.systems + 1):
        system, u, y, u_val, y_val = records(seed)
        poles = ", ".join(f"{p:.3f}" for p in sorted(np.linalg.eigvals(system[0]), key=lambda z: z.imag))
        times = {}
        rows = []
        for name, fitter in (("DSR_e", fit_dsr_e), (peer_name, fit_peer)):
            order, fit_pct, err = evaluate(fitter(u, y), system, u_val, y_val)
            times[name] = median_time(lambda f=fitter, u=u, y=y: f(u, y), args.repeats)
            rows.append((name, order, fit_pct, err))
        for name, order, fit_pct, err in rows:
            lines.append(
                f"| {seed} | {poles} | {name} | {order} | {fit_pct:.2f} | {err:.3f} | "
                f"{times[name] * 1e3:.1f} | {times[name] / times[peer_name]:.2f} |"
            )
    table = "\n".join(lines) + "\n"
    print(table)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_text(OUT, table)


if __name__ == "__main__":
    main()
