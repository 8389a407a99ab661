"""Time the five-level engine identification (structure search, IV parameters, lambda).

Prints the time of identification alone and of the whole embedded experiment (truth simulation
of the three records per level plus identification and validation), the median of several
repeats, and as a same-run reference the time of one 200x200 LU solve repeated 100 times, so
that figures from different (shared, noisy) machines can be compared as ratios.

    python experiments/bench_engine_identification.py [--repeats 7]
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg

from ssme_envs.identification.alpha_canonical import identify
from ssme_envs.identification.pipeline import default_experiment, run_default
from ssme_envs.models.engine import POWER_LEVELS
from ssme_envs.script_options import int_within, script_parser


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int_within(1), default=7)
    args = parser.parse_args()
    records = {p: default_experiment(p)["identification"] for p in POWER_LEVELS}

    def identify_all() -> None:
        for rec in records.values():
            identify(rec.u, rec.y, rec.dt)

    rng = np.random.default_rng(0)
    mat = rng.standard_normal((200, 200))

    def reference() -> None:
        for _ in range(100):
            scipy.linalg.lu_factor(mat)

    t_ident = _median_time(identify_all, args.repeats)
    t_full = _median_time(run_default, args.repeats)
    t_ref = _median_time(reference, args.repeats)
    print(f"five-level identification      : {t_ident * 1e3:8.1f} ms  ({t_ident / t_ref:6.2f} x reference)")
    print(f"five-level experiment + ident. : {t_full * 1e3:8.1f} ms  ({t_full / t_ref:6.2f} x reference)")
    print(f"reference (100 LU 200x200)     : {t_ref * 1e3:8.1f} ms")
    print(f"target: identification under 1 s -> {'met' if t_ident < 1.0 else 'NOT met'}")


if __name__ == "__main__":
    main()
