"""Time of the evaluation harness: 100 episodes x 4 controllers on EngineTracking.

The four controllers (decoupled PI, LQ servo, MPC, LQ servo designed on the truth) each run 100
episodes of the default scenario (the full truth, 250 steps) through ``ssme_envs.evaluation``;
the reference measured in the same run is the same 100 episodes stepped with the zero action,
the floor any controller adds to. Prints and writes experiments/results/bench_evaluation.md.

    python experiments/bench_evaluation.py
"""

from __future__ import annotations

import time
from pathlib import Path

from agents import parse_controller
from ssme_envs.evaluation import evaluate
from ssme_envs.outputs import write_text
from ssme_envs.script_options import script_parser

ENV = "ssme_envs/EngineTracking-v0"
OUT = Path(__file__).resolve().parent / "results" / "bench_evaluation.md"


def _seconds(specs: list[str], episodes: int = 100) -> float:
    start = time.perf_counter()
    evaluate(ENV, {s: parse_controller(s, ENV) for s in specs}, ["noise"], episodes=episodes)
    return time.perf_counter() - start


def main() -> None:
    _seconds(["zero"], 2)  # imports and first-call costs out of the timings
    reference = min(_seconds(["zero"]) for _ in range(3))
    rows = []
    for spec in ("pi", "lqi", "mpc", "lqi:truth"):
        rows.append((spec, min(_seconds([spec]) for _ in range(3))))
    total = _seconds(["pi", "lqi", "mpc", "lqi:truth"])
    lines = [
        "# Evaluation harness time",
        "",
        "Command: `python experiments/bench_evaluation.py`. 100 episodes (250 steps each) of the "
        "`noise` scenario (the full truth) on EngineTracking-v0, best of 3; the reference is the same "
        "episodes with the zero action, measured in the same run.",
        "",
        "| controller | s | x zero-action run |",
        "|---|---|---|",
        f"| zero (reference) | {reference:.2f} | 1.0 |",
    ]
    lines += [f"| {spec} | {sec:.2f} | {sec / reference:.1f} |" for spec, sec in rows]
    lines += ["", f"All four in one `evaluate` call: {total:.1f} s (the bound held to: 30 s)."]
    write_text(OUT, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    script_parser(__doc__.splitlines()[0]).parse_args()  # --help; any argument refused
    main()
