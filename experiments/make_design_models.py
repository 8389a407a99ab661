"""Regenerate the packaged design models in src/ssme_envs/models/data/.

- engine_identified_<power>.json: the engine pipeline on the embedded PRBS experiment at the five
  Table I power levels, default seed;
- nozzle_identified.json: the nozzle pipeline on the embedded bench test of Table 1's nozzle;
- nozzle_strong_identified.json: the same on the strong-hysteresis nozzle (the "strong" plant).

The test suite regenerates them and checks that the packaged files are unchanged.

    python experiments/make_design_models.py [--only engine|nozzle]
"""

from __future__ import annotations

from pathlib import Path

from ssme_envs.identification import nozzle_pipeline
from ssme_envs.identification.pipeline import DEFAULT_SEED, run_default
from ssme_envs.models.nozzle import IDENTIFIED_FILES
from ssme_envs.script_options import script_parser

DATA = Path(__file__).resolve().parents[1] / "src" / "ssme_envs" / "models" / "data"


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("engine", "nozzle"))
    args = parser.parse_args()
    if args.only in (None, "engine"):
        for result in run_default(seed=DEFAULT_SEED):
            path = DATA / f"engine_identified_{result.power_percent}.json"
            result.identified.model.save(path)
            print(f"wrote {path.name}: indices {list(result.identified.model.observability_indices)}")
    if args.only in (None, "nozzle"):
        for truth, name in IDENTIFIED_FILES.items():
            model = nozzle_pipeline.run_default(truth=truth)[0].model
            model.save(DATA / name)
            print(f"wrote {name}: {model.fit['bouc_wen']['reason']}")


if __name__ == "__main__":
    main()
