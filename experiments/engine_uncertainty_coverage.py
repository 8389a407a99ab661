"""Coverage of the engine identification's 95 % intervals over noise seeds.

For each Table I power level: the 8-period PRBS experiment (1016 samples, amplitude 0.01) on the
point model with white output noise of 5 % of each output's spread, identified with the
defaults, repeated over noise seeds. Counts how often the 95 % interval (estimate +- 1.96
standard errors, delta method on the model's covariance) contains the true value, for the first
10 Markov parameters (40 numbers) and for lambda; a well-calibrated covariance gives about 95 %.

Only seeds whose model has the true indices (2, 2) are counted; ``--indices`` gives the indices
instead of the structure search (a structure other than (2, 2) then leaves nothing to count).

    python experiments/engine_uncertainty_coverage.py [--seeds 200] [--levels 100] [--methods iv,ls,oe]
        [--indices 2,2]
"""

from __future__ import annotations

import argparse

import numpy as np
from tqdm import tqdm

from ssme_envs.cli_checks import positive_integers
from ssme_envs.identification import identify
from ssme_envs.identification.arguments import METHODS
from ssme_envs.identification.covariance import markov_standard_errors
from ssme_envs.models import POWER_LEVELS, TruthConfig, published_model, simulate
from ssme_envs.script_options import comma_choices, float_within, int_within, script_parser
from ssme_envs.signals import prbs

COUNT = 10


def index_pair(text: str) -> tuple[int, int]:
    """``--indices``: the observability indices of the engine's two outputs, e.g. 2,2."""
    try:
        values = positive_integers("--indices", text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if len(values) != 2:
        raise argparse.ArgumentTypeError(f"--indices needs one index per output (two), got {text!r}")
    return values


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=200)
    parser.add_argument(
        "--levels",
        type=comma_choices([str(p) for p in POWER_LEVELS]),
        default=",".join(str(p) for p in POWER_LEVELS),
    )
    parser.add_argument(
        "--noise",
        type=float_within(0.0, 1.0, above=True),  # without noise the intervals have nothing to cover
        default=0.05,
        help="std, fraction of each output's spread",
    )
    parser.add_argument(
        "--methods", type=comma_choices(METHODS), default="iv", help=f"comma-separated: {', '.join(METHODS)}"
    )
    parser.add_argument(
        "--indices", type=index_pair, help="observability indices given (default: the structure search's)"
    )
    args = parser.parse_args()
    u = prbs(1016, amplitude=0.01)
    print(f"{args.seeds} noise seeds, white output noise {args.noise:.0%} of each output's spread\n")
    print("| power % | method | indices right | Markov coverage (mean, min-max of 40) | lambda coverage |")
    print("|---|---|---|---|---|")
    for power in (int(v) for v in args.levels.split(",")):
        truth = published_model(power)
        clean = simulate(truth, u, TruthConfig.ideal())[1]
        want = truth.markov_parameters(COUNT)
        for method in args.methods.split(","):
            hits, lam_hits, right, refused = [], [], 0, 0
            for seed in tqdm(range(args.seeds), desc=f"{power} % {method}", leave=False):
                rng = np.random.default_rng([seed, power])
                y = clean + args.noise * clean.std(axis=0) * rng.standard_normal(clean.shape)
                try:
                    model = identify(u, y, 0.04, method=method, indices=args.indices).model
                except ValueError:  # refused, as the identifier does on data too noisy for its ranks
                    refused += 1
                    continue
                if model.observability_indices != (2, 2):
                    continue
                right += 1
                estimate, se = markov_standard_errors(model, COUNT)
                hits.append(np.abs(estimate - want) <= 1.96 * se)
                lam_se = model.uncertainty.standard_errors[-model.n_inputs :]
                lam_hits.append(np.abs(model.lam - truth.lam) <= 1.96 * lam_se)
            counted = f"{right}/{args.seeds}" + (f" ({refused} refused)" if refused else "")
            if not hits:  # no seed gave the true indices: no interval to count
                print(f"| {power} | {method} | {counted} | - | - |")
                continue
            per = np.mean(hits, axis=0).ravel()
            lam = np.mean(lam_hits, axis=0)
            print(
                f"| {power} | {method} | {counted} | {per.mean():.1%} "
                f"({per.min():.1%}-{per.max():.1%}) | {', '.join(f'{v:.1%}' for v in lam)} |"
            )


if __name__ == "__main__":
    main()
