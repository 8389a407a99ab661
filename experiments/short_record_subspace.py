"""DSR_e's automatic past horizon on short records: the record's cap alone, and with a pass at the
horizon rule's length kept where its BIC on the record is lower.

Two families of stable SISO systems: the tests' ``conftest.random_system`` of order 2-5 (poles of
radius 0.3-0.9), and lightly damped ones of two rotation blocks (4 states, poles of radius
0.95-0.995 at angles 0.1-1.2 rad, Gaussian B and C); one Gaussian input, 300 samples, white
output noise 5 % of the output's spread. A record this short caps
the automatic past horizon below its rule (``subspace_horizons.rule_past``); each record is
identified by ``dsr_e`` with its automatic horizons (which try the rule's horizon too) and with
the capped horizon given (the automatic pass alone). Each model simulates a fresh noise-free
record of 3000 samples (scipy.signal.dlsim): error relative to the output's spread.

    python experiments/short_record_subspace.py [--seeds 40]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.linalg
from tqdm import tqdm

from ssme_envs.identification.subspace import dsr_e
from ssme_envs.identification.subspace_horizons import default_future, default_past
from ssme_envs.script_options import int_within, script_parser

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import dlsim, random_system  # the systems and simulation the tests use

SAMPLES, FRESH, NOISE, MAX_ORDER = 300, 3000, 0.05, 10
FAMILIES = {"random": "random_system, order 2-5", "slow": "lightly damped, 4 states"}


def lightly_damped(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two rotation blocks of radius 0.95-0.995 and angle 0.1-1.2 rad, Gaussian B and C."""
    blocks = []
    for radius, angle in zip(rng.uniform(0.95, 0.995, 2), rng.uniform(0.1, 1.2, 2), strict=True):
        blocks.append(radius * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]))
    return scipy.linalg.block_diag(*blocks), rng.normal(size=(4, 1)), rng.normal(size=(1, 4))


def record_errors(seed: int, family: str) -> tuple[float, float, int, int]:
    """Fresh-record errors of the automatic horizons and of the capped horizon alone, with the
    past horizons they used."""
    rng = np.random.default_rng(seed)
    a, b, c = random_system(int(rng.integers(2, 6)), 1, 1, rng) if family == "random" else lightly_damped(rng)
    u = rng.standard_normal((SAMPLES, 1))
    y = dlsim(a, b, c, u)
    y = y + NOISE * y.std() * rng.standard_normal(y.shape)
    fresh_u = rng.standard_normal((FRESH, 1))
    fresh = dlsim(a, b, c, fresh_u)
    capped = default_past(SAMPLES, 1, 1, default_future(MAX_ORDER, 1))
    fits = [dsr_e(u, y, 1.0), dsr_e(u, y, 1.0, past_horizon=capped)]
    errors = [float(np.linalg.norm(fresh - dlsim(f.model.A, f.model.B, f.model.C, fresh_u)) /
                    np.linalg.norm(fresh - fresh.mean())) for f in fits]  # fmt: skip
    return errors[0], errors[1], fits[0].past_horizon, fits[1].past_horizon


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=40)
    args = parser.parse_args()
    print(f"seeds 0-{args.seeds - 1} of each family, SISO, {SAMPLES} samples, {NOISE:.0%} output noise\n")
    print("| systems | past horizon | error median / 90th pct / max | records that kept the rule's horizon |")
    print("|---|---|---|---|")
    for family, title in FAMILIES.items():
        rows = np.array([record_errors(s, family) for s in tqdm(range(args.seeds), desc=family, leave=False)])
        for k, label in enumerate(["automatic", "capped alone"]):
            err = rows[:, k]
            kept = f"{int(np.sum(rows[:, 2] > rows[:, 3]))} of {len(rows)}" if k == 0 else "-"
            print(f"| {title} | {label} | {np.median(err):.3g} / {np.percentile(err, 90):.3g} / "
                  f"{err.max():.3g} | {kept} |")  # fmt: skip


if __name__ == "__main__":
    main()
