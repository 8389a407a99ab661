"""How the engine identification holds up under output noise: indices, rank-search margin, SEE.

For each Table I power level, noise level (std as a share of each output's std) and record
length: identify with least squares (eq 27) and with the IV refinement, then report the
observability indices found, the largest ratio among rows judged dependent (the rank-search
margin, to compare with rank_tol = 0.1) and the worst model SEE on a fresh noise-free PRBS
and on the low-frequency test. Writes experiments/results/engine_noise_study.md.

    python experiments/engine_noise_study.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ssme_envs.identification import identify, model_prediction, see
from ssme_envs.models import POWER_LEVELS, TruthConfig, published_model, simulate
from ssme_envs.outputs import write_text
from ssme_envs.script_options import script_parser
from ssme_envs.signals import prbs, step_ramp_test_signal

NOISE = (0.0, 0.01, 0.05, 0.10)
LENGTHS = (500, 2000, 8000)
OUT = Path(__file__).resolve().parent / "results" / "engine_noise_study.md"


def main() -> None:
    checks = {"prbs": prbs(254, variant=1), "low-frequency": step_ramp_test_signal()}
    lines = [
        "# Engine identification under output noise",
        "",
        "Seeded (numpy default_rng(power * 1000 + N + round(1000 * noise))); command: "
        "`python experiments/engine_noise_study.py`.",
        "",
        "| power % | noise | N | indices | max dependent ratio | worst SEE, LS | worst SEE, IV |",
        "|---|---|---|---|---|---|---|",
    ]
    for power in POWER_LEVELS:
        truth = published_model(power)
        truth_val = {k: simulate(truth, u, TruthConfig.ideal())[1] for k, u in checks.items()}
        for noise in NOISE:
            for n in LENGTHS:
                rng = np.random.default_rng(power * 1000 + n + round(1000 * noise))
                u = prbs(n)
                _, clean = simulate(truth, u, TruthConfig.ideal())
                y = clean + noise * clean.std(axis=0) * rng.standard_normal(clean.shape)
                worst = {}
                for method in ("ls", "iv"):
                    result = identify(u, y, 0.04, method=method)
                    worst[method] = max(
                        float(np.max(see(truth_val[k], model_prediction(result.model, checks[k]))))
                        for k in checks
                    )
                dependent = [r for *_, r, kept in result.search.ratios if not kept]
                lines.append(
                    f"| {power} | {noise:.0%} | {n} | {list(result.model.observability_indices)} | "
                    f"{max(dependent):.2e} | {worst['ls']:.2e} | {worst['iv']:.2e} |"
                )
        print(f"{power} % done")
    write_text(OUT, "\n".join(lines) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    script_parser(__doc__.splitlines()[0]).parse_args()  # --help; any argument refused
    main()
