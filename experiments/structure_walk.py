"""The automatic structure of ``identify`` on high-order systems, against the true indices given.

Random stable systems (the tests' ``conftest.random_system``: real and complex pole blocks of
radius 0.3-0.9 behind a random change of basis) of order 6-10, one Gaussian input, 2000 samples,
white output noise: 1e-6 of each output's spread with one output, 1 % with one or two. Each record
is identified twice, with the automatic structure and with the system's own observability indices
(a rank computation on (A, C)); both models simulate a fresh noise-free record (scipy.signal.dlsim),
error relative to the output's spread, the largest over the outputs. Only the public ``identify``
is called, so the script runs on any version of the package.

    python experiments/structure_walk.py [--seeds 200] [--first 100]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ssme_envs.identification import identify
from ssme_envs.script_options import int_within, script_parser

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import dlsim, eq36, random_system  # the systems and simulation the tests use
from test_identification_structures import observability_indices

SAMPLES = 2000
CASES = ((1e-6, 1), (0.01, 2))  # (noise, largest output count)


def record_errors(seed: int, noise: float, outputs: int) -> tuple[int, int, float, float]:
    """(true order, automatic order, automatic error, true indices' error) of one record."""
    rng = np.random.default_rng(seed)
    order, p = int(rng.integers(6, 11)), int(rng.integers(1, outputs + 1))
    a, b, c = random_system(order, 1, p, rng)
    u = rng.standard_normal((SAMPLES, 1))
    y = dlsim(a, b, c, u)
    y = y + noise * y.std(axis=0) * rng.standard_normal(y.shape)
    fresh_u = rng.standard_normal((SAMPLES, 1))
    fresh = dlsim(a, b, c, fresh_u)

    def error(model) -> float:
        got = dlsim(model.A, model.B, model.C, eq36(fresh_u, model.lam))
        return float(np.max(np.sqrt(np.mean((fresh - got) ** 2, axis=0)) / fresh.std(axis=0)))

    auto = identify(u, y, 1.0, uncertainty=False).model
    given = identify(u, y, 1.0, indices=observability_indices(a, c), uncertainty=False).model
    return order, sum(auto.observability_indices), error(auto), error(given)


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=200)
    parser.add_argument("--first", type=int_within(0), default=100, help="first seed (default: 100)")
    args = parser.parse_args()
    print(f"seeds {args.first}-{args.first + args.seeds - 1}, order 6-10, one input, {SAMPLES} samples\n")
    print("| noise | outputs | order found | automatic error, median / 90th pct / max | true indices' error, "
          "median / max | automatic > 1.5 x true + 1e-4 | automatic > 3 x true + 2e-3 |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for noise, outputs in CASES:
        seeds = range(args.first, args.first + args.seeds)
        rows = np.array(
            [record_errors(s, noise, outputs) for s in tqdm(seeds, desc=f"noise {noise:g}", leave=False)]
        )
        found, auto, true = np.mean(rows[:, 1] == rows[:, 0]), rows[:, 2], rows[:, 3]
        label = "1" if outputs == 1 else f"1-{outputs}"
        spread = f"{np.median(auto):.2e} / {np.percentile(auto, 90):.2e} / {auto.max():.2e}"
        misses = f"{np.sum(auto > 1.5 * true + 1e-4)} | {np.sum(auto > 3 * true + 2e-3)}"
        true_spread = f"{np.median(true):.2e} / {true.max():.2e}"
        print(f"| {noise:g} | {label} | {found:.0%} | {spread} | {true_spread} | {misses} |")


if __name__ == "__main__":
    main()
