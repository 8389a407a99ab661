"""DSR_e's automatic order on noisy records: BIC of the one-step prediction errors against the
largest singular-value drop alone.

Random stable systems (the tests' ``conftest.random_system``: real and complex pole blocks of
radius 0.3-0.9 behind a random change of basis) of order 2-6 with 1-2 inputs and outputs, white
Gaussian inputs, 2000 samples, white output noise of 1, 5 and 20 % of each output's spread. For
each record the automatic order (BIC) and the largest drop of the same run's singular values
(fitted at the same horizons) are compared with the true order, and each model's simulation of a
fresh noise-free record (scipy.signal.dlsim) is compared with the truth: error relative to the
output's spread, the largest over the outputs.

    python experiments/subspace_order.py [--seeds 40]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.signal
from tqdm import tqdm

from ssme_envs.identification.subspace import _largest_drop, _order_candidates, dsr_e
from ssme_envs.script_options import int_within, script_parser

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import random_system  # the systems the tests draw

NOISES = (0.01, 0.05, 0.2)
SAMPLES = 2000


def response(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
    return scipy.signal.dlsim((a, b, c, d, 1.0), u)[1].reshape(u.shape[0], c.shape[0])


def simulation_error(model, truth: np.ndarray, u: np.ndarray) -> float:
    error = response(model.A, model.B, model.C, model.D, u) - truth
    return float(np.max(np.linalg.norm(error, axis=0) / np.linalg.norm(truth - truth.mean(axis=0), axis=0)))


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=40)
    args = parser.parse_args()
    rows = {noise: [] for noise in NOISES}
    for seed in tqdm(range(args.seeds), desc="systems", leave=False):
        rng = np.random.default_rng(seed)
        n, m, p = int(rng.integers(2, 7)), int(rng.integers(1, 3)), int(rng.integers(1, 3))
        a, b, c = random_system(n, m, p, rng)
        zero = np.zeros((p, m))
        u = rng.standard_normal((SAMPLES, m))
        clean = response(a, b, c, zero, u)
        fresh_u = rng.standard_normal((3000, m))
        fresh = response(a, b, c, zero, fresh_u)
        for noise in NOISES:
            y = clean + noise * clean.std(axis=0) * rng.standard_normal(clean.shape)
            bic = dsr_e(u, y, 1.0)
            horizons = {"past_horizon": bic.past_horizon, "future_horizon": bic.future_horizon}
            candidates = _order_candidates(bic.singular_values, min(10, len(bic.singular_values) - 1), False)
            drop_order = _largest_drop(bic.singular_values, candidates)
            drop = dsr_e(u, y, 1.0, order=drop_order, **horizons)
            true = dsr_e(u, y, 1.0, order=n)
            rows[noise].append(
                (
                    n,
                    drop_order,
                    bic.order,
                    *(simulation_error(r.model, fresh, fresh_u) for r in (drop, bic, true)),
                )
            )
    print(f"{args.seeds} random systems (order 2-6, 1-2 inputs and outputs), {SAMPLES} samples each\n")
    print("| noise | order found: largest drop | BIC | simulation error, median / 90th percentile: "
          "largest drop | BIC | true order |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for noise, table in rows.items():
        t = np.array(table)
        errors = [f"{np.median(t[:, k]):.2%} / {np.percentile(t[:, k], 90):.2%}" for k in (3, 4, 5)]
        print(f"| {noise:.0%} | {np.mean(t[:, 1] == t[:, 0]):.0%} | {np.mean(t[:, 2] == t[:, 0]):.0%} | "
              + " | ".join(errors) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
