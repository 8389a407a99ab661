"""Regenerate the packaged engine design models (src/ssme_envs/models/data/engine_identified_*.json).

They are the pipeline's output on the embedded experiment with the default seed; the test
suite regenerates them in memory and checks that the packaged files are unchanged.

    python experiments/make_engine_design_models.py
"""

from __future__ import annotations

from pathlib import Path

from ssme_envs.identification.pipeline import DEFAULT_SEED, run_default

DATA = Path(__file__).resolve().parents[1] / "src" / "ssme_envs" / "models" / "data"


def main() -> None:
    for result in run_default(seed=DEFAULT_SEED):
        path = DATA / f"engine_identified_{result.power_percent}.json"
        result.identified.model.save(path)
        print(f"wrote {path.name}: indices {list(result.identified.model.observability_indices)}")


if __name__ == "__main__":
    main()
