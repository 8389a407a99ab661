"""Coverage of the 95 % intervals of methods iv and oe where iv keeps the least-squares estimate.

A second-order SISO system with a slow pole nearly cancelled by a zero (poles 0.896 and 0.561,
zero 0.855, gain -1.009, sample time 1 s), a Gaussian input, 1000 samples, white output noise of
``--noise`` of the output's spread, identified with indices (2,) and no asymmetric gains. Its weak
slow mode makes the instrumental-variable passes of method "iv" simulate the record worse than
least squares in many seeds, and the least-squares estimate is biased under white output noise.
Counts how often each method's interval (estimate +- 1.96 standard errors) holds the true value,
for the first 8 Markov parameters, over all seeds and over the seeds where "iv" kept least
squares.

    python experiments/slow_mode_coverage.py [--seeds 200] [--noise 0.1]
"""

from __future__ import annotations

import numpy as np
import scipy.signal
from tqdm import tqdm

from ssme_envs.identification import identify
from ssme_envs.identification.covariance import markov_standard_errors
from ssme_envs.script_options import float_within, int_within, script_parser

ZEROS, POLES, GAIN = [0.855], [0.896, 0.561], -1.009
COUNT = 8
SAMPLES = 1000


def _truth_markov(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """C A^k B, k < COUNT."""
    return np.array([c @ np.linalg.matrix_power(a, k) @ b for k in range(COUNT)])


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=200)
    parser.add_argument(
        "--noise",
        type=float_within(0.0, 1.0, above=True),
        default=0.1,
        help="std, fraction of the output's spread",
    )
    args = parser.parse_args()
    a, b, c, d = scipy.signal.zpk2ss(ZEROS, POLES, GAIN)
    want = _truth_markov(a, b, c)
    hits: dict[str, list[np.ndarray]] = {"iv": [], "oe": []}
    kept_ls: list[bool] = []
    for seed in tqdm(range(args.seeds), desc="seeds", leave=False):
        rng = np.random.default_rng(seed)
        u = rng.standard_normal((SAMPLES, 1))
        y = scipy.signal.dlsim((a, b, c, d, 1.0), u)[1]
        y = y + args.noise * y.std() * rng.standard_normal(y.shape)
        for method in hits:
            model = identify(u, y, 1.0, indices=[2], asymmetric=False, method=method).model
            estimate, se = markov_standard_errors(model, COUNT)
            hits[method].append((np.abs(estimate - want) <= 1.96 * se).ravel())
            if method == "iv":
                kept_ls.append(model.uncertainty.method.startswith("least squares"))
    kept = np.array(kept_ls)
    print(f"{args.seeds} noise seeds, white output noise {args.noise:.0%} of the output's spread; ", end="")
    print(f"method iv kept least squares in {kept.sum()} of them\n")
    print("| method | coverage, all seeds | coverage, seeds where iv kept least squares | the others |")
    print("|---|---|---|---|")
    for method, rows in hits.items():
        table = np.array(rows)
        parts = [table, table[kept], table[~kept]]
        print(f"| {method} | " + " | ".join("-" if not len(p) else f"{p.mean():.1%}" for p in parts) + " |")


if __name__ == "__main__":
    main()
