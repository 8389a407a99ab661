"""Time ``import ssme_envs`` and the first ``gymnasium.make`` + reset of each env, each in a fresh
interpreter (the best of --rounds), and name the heavy scipy modules the make imported.

    python experiments/import_time.py [--rounds 5]

Writes experiments/results/import_time.md.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ssme_envs.envs import catalogue
from ssme_envs.outputs import write_text
from ssme_envs.script_options import int_within, script_parser

RESULTS = Path(__file__).resolve().parent / "results" / "import_time.md"
HEAVY = ("scipy.interpolate", "scipy.signal", "scipy.linalg", "scipy.optimize", "scipy.integrate")
PROBE = """
import json, sys, time
t0 = time.perf_counter()
import gymnasium as gym, ssme_envs
t1 = time.perf_counter()
gym.make({env_id!r}).reset(seed=0)
t2 = time.perf_counter()
print(json.dumps([t1 - t0, t2 - t1, [m for m in {heavy!r} if m in sys.modules]]))
"""


def measure(env_id: str, rounds: int) -> tuple[float, float, list[str]]:
    """Best import time, best first make + reset time (s) and the heavy modules imported."""
    runs = []
    for _ in range(rounds):
        code = PROBE.format(env_id=env_id, heavy=HEAVY)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        runs.append(json.loads(out.stdout))
    return min(r[0] for r in runs), min(r[1] for r in runs), runs[-1][2]


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int_within(1), default=5)
    args = parser.parse_args()
    lines = [
        "# Import and first make",
        "",
        f"Command: `python experiments/import_time.py --rounds {args.rounds}`. Each round a fresh "
        "interpreter imports gymnasium and ssme_envs, then makes and resets one env; the best round "
        "of each figure (s). Heavy modules: those of "
        f"{', '.join(HEAVY)} that the make left imported.",
        "",
        "| env | import gymnasium + ssme_envs | first make + reset | together | heavy modules imported |",
        "|---|---|---|---|---|",
    ]
    for env_id in catalogue.ENVS:
        imported, made, heavy = measure(env_id, args.rounds)
        lines.append(
            f"| {env_id} | {imported:.3f} | {made:.3f} | {imported + made:.3f} | {', '.join(heavy) or '-'} |"
        )
        print(lines[-1], flush=True)
    write_text(RESULTS, "\n".join(lines) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
