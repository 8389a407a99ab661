"""How often the default structure choice keeps a weakly observable mode.

The record of ``tests/test_identification_structures.py::weak_mode_record`` (a 4-state system
with observability indices (2, 2) whose second pair of states reaches the outputs through a
coupling of 0.02, hidden in a random basis, random binary inputs, 1 % output noise, 1,200
samples), over many noise and basis seeds: the indices the rank rule alone gives and those the
identification chooses.

    python experiments/weak_mode_structure.py [--seeds 100] [--out experiments/results/weak_mode_structure.md]
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_identification_structures import weak_mode_record

from ssme_envs.identification import identify
from ssme_envs.outputs import write_text
from ssme_envs.script_options import int_within, output_file, script_parser


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int_within(1), default=100)
    parser.add_argument("--out", type=output_file, default=None)
    args = parser.parse_args()
    rank_rule, chosen, margins = collections.Counter(), collections.Counter(), []
    for seed in tqdm(range(args.seeds), desc="seeds"):
        u, y, _ = weak_mode_record(seed)
        result = identify(u, y, 0.04)
        rank_rule[result.search.rank_rule] += 1
        chosen[result.model.observability_indices] += 1
        margins.append(result.search.margin)
    lines = [
        "Command: `python experiments/weak_mode_structure.py`",
        "",
        f"{args.seeds} seeds of a 4-state (2, 2) system with a weakly observable mode, "
        "1 % noise, 1,200 samples.",
        "",
        "| indices | rank rule alone | chosen by default |",
        "|---|---|---|",
    ]
    for indices in sorted(set(rank_rule) | set(chosen)):
        lines.append(f"| {list(indices)} | {rank_rule[indices]} | {chosen[indices]} |")
    margins.sort()
    median = margins[len(margins) // 2]
    lines += ["", f"Margin to the runner-up: smallest {margins[0]:.1f}, median {median:.1f}."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out is not None:
        write_text(args.out, text)


if __name__ == "__main__":
    main()
