"""The automatic structure of ``identify`` on short noisy MIMO records, methods iv and oe.

Random stable systems (the tests' ``conftest.random_system``) of order 3-6, two Gaussian inputs,
two outputs, 300 samples, white output noise 5 % of each output's spread. Each record is
identified with the automatic structure under each method and, for comparison, with the system's
own observability indices (a rank computation on (A, C)) under method iv; every model simulates a
fresh noise-free record of 4000 samples (scipy.signal.dlsim), error relative to the output's
spread, the larger of the two outputs. Only the public ``identify`` is called, so the script runs
on any version of the package.

    python experiments/short_record_structure.py [--seeds 40] [--first 100] [--methods iv,oe]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ssme_envs.identification import identify
from ssme_envs.script_options import comma_choices, int_within, script_parser

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import dlsim, eq36, random_system  # the systems and simulation the tests use
from test_identification_structures import observability_indices

SAMPLES, FRESH, NOISE = 300, 4000, 0.05


def record_errors(seed: int, methods: list[str]) -> list[float]:
    """Fresh-record errors of the automatic structure under each method, then of the true indices
    under iv (NaN where identify refuses the record)."""
    rng = np.random.default_rng(seed)
    a, b, c = random_system(int(rng.integers(3, 7)), 2, 2, rng)
    u = rng.standard_normal((SAMPLES, 2))
    y = dlsim(a, b, c, u)
    y = y + NOISE * y.std(axis=0) * rng.standard_normal(y.shape)
    fresh_u = rng.standard_normal((FRESH, 2))
    fresh = dlsim(a, b, c, fresh_u)

    def error(**options) -> float:
        try:
            model = identify(u, y, 1.0, uncertainty=False, **options).model
        except ValueError:
            return float("nan")
        got = dlsim(model.A, model.B, model.C, eq36(fresh_u, model.lam))
        return float(np.max(np.sqrt(np.mean((fresh - got) ** 2, axis=0)) / fresh.std(axis=0)))

    return [error(method=m) for m in methods] + [error(indices=observability_indices(a, c))]


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=40)
    parser.add_argument("--first", type=int_within(0), default=100, help="first seed (default: 100)")
    parser.add_argument("--methods", type=comma_choices(["iv", "ls", "oe"]), default="iv,oe")
    args = parser.parse_args()
    methods = args.methods.split(",")
    seeds = range(args.first, args.first + args.seeds)
    rows = np.array([record_errors(s, methods) for s in tqdm(seeds, desc="records", leave=False)])
    refused = int(np.sum(np.isnan(rows).any(axis=1)))
    rows = rows[~np.isnan(rows).any(axis=1)]
    true = rows[:, -1]
    print(f"seeds {seeds[0]}-{seeds[-1]}, order 3-6, 2 inputs, 2 outputs, {SAMPLES} samples, "
          f"{NOISE:.0%} output noise; {len(rows)} records ({refused} refused by identify)\n")  # fmt: skip
    print("| structure, method | error median / 90th pct / max | > 1.5 x true indices' (iv) + 1e-3 |")
    print("|---|---|---|")
    for k, label in enumerate([f"automatic, {m}" for m in methods] + ["true indices, iv"]):
        err = rows[:, k]
        worse = "-" if k == len(methods) else str(int(np.sum(err > 1.5 * true + 1e-3)))
        print(
            f"| {label} | {np.median(err):.3g} / {np.percentile(err, 90):.3g} / {err.max():.3g} | {worse} |"
        )


if __name__ == "__main__":
    main()
