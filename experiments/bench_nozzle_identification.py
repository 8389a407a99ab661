"""Time the end-to-end nozzle identification: the embedded bench test (2.5 kHz simulation of
59.8 s, decimation to N = 7476) plus DSR_e, the Bouc-Wen search and refinement, and validation.

Prints the median wall time of a few repeats and, as a same-run reference for noisy shared
machines, the time of 100 LU factorizations of a 200 x 200 matrix.

    python experiments/bench_nozzle_identification.py [--repeats 3] [--workers 2]
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg

from ssme_envs.identification.nozzle_pipeline import run_default
from ssme_envs.script_options import int_within, max_workers, script_parser


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int_within(1), default=3)
    parser.add_argument("--workers", type=int_within(1, max_workers()), default=2)
    args = parser.parse_args()
    mat = np.random.default_rng(0).standard_normal((200, 200))
    times, refs = [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        for _ in range(100):
            scipy.linalg.lu_factor(mat)
        refs.append(time.perf_counter() - start)
        start = time.perf_counter()
        ident, _ = run_default(workers=args.workers)
        times.append(time.perf_counter() - start)
    t, ref = float(np.median(times)), float(np.median(refs))
    print(f"end-to-end nozzle identification : {t:6.1f} s  ({t / ref:7.1f} x reference)")
    print(f"reference (100 LU 200x200)       : {ref * 1e3:6.1f} ms")
    print(f"target under 60 s -> {'met' if t < 60 else 'NOT met'}; {ident.bouc_wen.reason}")


if __name__ == "__main__":
    main()
