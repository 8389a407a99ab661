"""The identification pipeline on the nonlinear engine truth.

:func:`nonlinear_experiment` runs the embedded experiment of
:func:`~ssme_envs.identification.pipeline.default_experiment` (the same PRBS design and noise
streams, the figure 3 step/ramp test) on :class:`~ssme_envs.models.engine_nonlinear.NonlinearEngine`
at an operating point; :func:`run_nonlinear` identifies each Table I level from it with
:func:`~ssme_envs.identification.identify` and validates the models (SEE, eq 53).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ssme_envs.identification.metrics import validate
from ssme_envs.identification.pipeline import (
    DEFAULT_SEED,
    IDENTIFICATION_PERIODS,
    PRBS_AMPLITUDE,
    VALIDATION_PERIODS,
    EngineRecord,
    LevelResult,
    identify_record,
)
from ssme_envs.models.engine import POWER_LEVELS, TruthConfig, published_model
from ssme_envs.models.engine_nonlinear import NonlinearEngine, simulate_nonlinear
from ssme_envs.signals import prbs, step_ramp_test_signal


def nonlinear_experiment(
    power_percent: float,
    seed: int = DEFAULT_SEED,
    config: TruthConfig | None = None,
    engine: NonlinearEngine | None = None,
    test_scale: float = 1.0,
) -> dict[str, EngineRecord]:
    """The embedded experiment of :func:`ssme_envs.identification.pipeline.default_experiment`
    (same commands, same noise streams) on the nonlinear truth at one operating point.

    Parameters
    ----------
    power_percent : float
        Operating point, % (65-110).
    seed : int
        Seed of the sensor noise streams.
    config : TruthConfig, optional
        Valve and sensor effects (default ``TruthConfig()``).
    engine : NonlinearEngine, optional
        Default: the Table I engine.
    test_scale : float
        Factor on the figure 3 step/ramp signal (1: within +-0.02 normalized travel).

    Returns
    -------
    dict of EngineRecord
        "identification" (8 periods of 127-bit PRBS, +-0.01), "validation_prbs" (2 periods,
        another polynomial), "validation_low_frequency" (figure 3 signal times ``test_scale``);
        outputs are deviations from the operating point.
    """
    config = TruthConfig() if config is None else config
    engine = NonlinearEngine() if engine is None else engine
    commands = {
        "identification": prbs(127 * IDENTIFICATION_PERIODS, PRBS_AMPLITUDE),
        "validation_prbs": prbs(127 * VALIDATION_PERIODS, PRBS_AMPLITUDE, variant=1),
        "validation_low_frequency": test_scale * step_ramp_test_signal(engine.dt),
    }
    streams = np.random.SeedSequence([seed, round(power_percent)]).spawn(len(commands))
    records = {}
    for (name, u), stream in zip(commands.items(), streams, strict=True):
        y, _ = simulate_nonlinear(engine, power_percent, u, config, np.random.default_rng(stream))
        records[name] = EngineRecord(u, y, engine.dt)
    return records


def run_nonlinear(
    seed: int = DEFAULT_SEED,
    power_levels: Sequence[int] = POWER_LEVELS,
    config: TruthConfig | None = None,
    options: dict | None = None,
    engine: NonlinearEngine | None = None,
    test_scale: float = 1.0,
) -> list[LevelResult]:
    """Identify each Table I level from the nonlinear truth and validate it (the pipeline's
    :func:`~ssme_envs.identification.pipeline.run_default` with this truth).

    ``options`` go to :func:`ssme_envs.identification.identify`. Returns a list of
    :class:`~ssme_envs.identification.pipeline.LevelResult`, whose ``published`` is Table I's
    model at that level and whose ``validation`` holds SEE and fit per record.
    """
    engine = NonlinearEngine() if engine is None else engine
    truth = (
        f"nonlinear engine, tau {engine.tau:g} s, valve authority g {engine.authority_loss:g}, "
        f"b {engine.authority_travel:g}"
    )
    results = []
    for power in power_levels:
        records = nonlinear_experiment(power, seed, config, engine, test_scale)
        ident = identify_record(records["identification"], **(options or {}))
        model = ident.model
        model.fit.update(power_percent=power, seed=seed, truth=truth)
        validation = {
            name: validate(model, rec.u, rec.y) for name, rec in records.items() if name != "identification"
        }
        model.fit.update(validation)
        results.append(LevelResult(power, published_model(power), ident, records, validation))
    return results


def nonlinear_into(work: Path, seed: int = DEFAULT_SEED, test_scale: float = 1.0) -> Path:
    """Identify the five levels on the nonlinear truth (:func:`run_nonlinear`) and add their
    section (Table I beside the identified models, Table II's SEE beside ours) to
    ``work``/report.md, the embedded experiment's report. Returns the report's path."""
    from ssme_envs.identification import report

    results = run_nonlinear(seed, test_scale=test_scale)
    amplitude = np.abs(results[0].records["validation_low_frequency"].u).max(axis=0)
    section = report.nonlinear_section(results, seed, test_scale, amplitude.tolist())
    return report.append_section(Path(work) / "report.md", section)
