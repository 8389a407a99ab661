"""Numerical safety of the nozzle-driven envs.

The substep rule bounds every rate that limits RK4's stability (stiffness, damping, Bouc-Wen
hysteresis), plants that need more than MAX_SUBSTEPS are refused at construction, the loader
refuses non-physical plants, and a step whose state goes non-finite anyway ends its episode
with ``info["nonfinite"]`` and finite values, identically in the scalar env, the native vector
env and gymnasium's SyncVectorEnv. Unstable engine plants are refused.

The property runs over random plants also require that the guard never fires: with the
damping rate left out of the rule they fail (the guard then ends episodes cleanly, which the
documented contract alone would accept).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import ssme_envs  # noqa: F401
from ssme_envs.envs import nozzle_plants, nozzle_task
from ssme_envs.envs.launcher_pitch import LauncherTask
from ssme_envs.envs.nozzle_task import NozzleTask
from ssme_envs.envs.tracking_env import EpisodeOverError
from ssme_envs.models.engine import identified_model
from ssme_envs.models.nozzle import (
    MAX_SUBSTEPS,
    RK4_REAL_AXIS_LIMIT,
    STABLE_STEP_RATE,
    NozzleModel,
    NozzleParameters,
    identified_nozzle,
    published_nozzle,
    recommended_substeps,
    simulate_nozzle,
    stiff_rates,
)
from ssme_envs.models.nozzle_joint import MAX_N
from ssme_envs.models.statespace import AlphaCanonicalModel

NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"
ENGINE = "ssme_envs/EngineTracking-v0"
ENVELOPE = math.radians(6.0)
TORQUE = 3.0e4
# RK4 steps one hypothesis example may spend per env: a few hundred env steps for the plants
# that need up to a few hundred substeps, fewer (at least 20) for the costliest accepted ones
RK4_BUDGET = 60_000

SETTINGS = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)


def _log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(math.log10(low), math.log10(high)).map(lambda e: 10.0**e)


@st.composite
def plants(draw: st.DrawFn) -> NozzleParameters:
    """Joints the loader accepts over wide ranges: J 1e-8-1e3 kg m^2, b 0 or 1e-3-1e8 N m s/rad,
    k 1e-3-1e10 N m/rad; half of them Bouc-Wen with a in [0, 1], A 1e-3-1e3, n 0.1-10,
    gamma 0 or 1e-3-1e5, beta from -gamma to 1e5."""
    j = draw(_log_uniform(1e-8, 1e3))
    b = draw(st.one_of(st.just(0.0), _log_uniform(1e-3, 1e8)))
    k = draw(_log_uniform(1e-3, 1e10))
    if draw(st.booleans()):
        return NozzleParameters(J=j, b=b, k=k)
    gamma = draw(st.one_of(st.just(0.0), _log_uniform(1e-3, 1e5)))
    beta = draw(st.one_of(st.floats(-1.0, 0.0).map(lambda f: f * gamma), _log_uniform(1e-3, 1e5)))
    return NozzleParameters(
        J=j,
        b=b,
        k=k,
        a=draw(st.floats(0.0, 1.0)),
        A=draw(_log_uniform(1e-3, 1e3)),
        beta=beta,
        gamma=gamma,
        n=draw(_log_uniform(0.1, 10.0)),
    )


def _assert_same(x: Any, y: Any, where: str) -> None:
    """Equal values, arrays (object arrays element by element) and nested info dicts."""
    if isinstance(x, tuple | list):
        assert isinstance(y, tuple | list) and len(x) == len(y), where
        for i, (a, b) in enumerate(zip(x, y, strict=True)):
            _assert_same(a, b, f"{where}[{i}]")
    elif isinstance(x, dict):
        assert isinstance(y, dict) and sorted(x) == sorted(y), f"{where}: keys {sorted(x)} != {sorted(y)}"
        for key in x:
            _assert_same(x[key], y[key], f"{where}[{key!r}]")
    elif isinstance(x, np.ndarray) and x.dtype == object:
        assert isinstance(y, np.ndarray) and y.shape == x.shape, where
        for i, (a, b) in enumerate(zip(x, y, strict=True)):
            _assert_same(a, b, f"{where}[{i}]")
    else:
        assert np.array_equal(x, y), f"{where}: {x!r} != {y!r}"
        assert np.asarray(x).dtype == np.asarray(y).dtype, f"{where}: dtypes differ"


def _check_step(result: tuple, where: str) -> None:
    """Finite observations and rewards; the nonfinite flag only on terminated steps."""
    obs, reward, terminated, _, info = result
    assert np.all(np.isfinite(obs)), f"{where}: non-finite observation {obs}"
    assert np.all(np.isfinite(reward)), f"{where}: non-finite reward {reward}"
    for flags in (info, info.get("final_info", {})):
        if "nonfinite" in flags:
            assert np.all(terminated[flags["_nonfinite"]]), f"{where}: flagged but not terminated"


def _run_against_sync(env_id: str, plant: NozzleParameters, mode: AutoresetMode, seed: int) -> int:
    """Step the native vector env and SyncVectorEnv (2 sub-envs) with the same random actions,
    and the scalar env alongside sub-env 0 (autoreset by hand as NEXT_STEP does); every output
    must be finite and the three must agree bit for bit (infos included). Returns the steps."""
    try:
        native = gym.make_vec(
            env_id, 2, vectorization_mode="vector_entry_point", autoreset_mode=mode, plant=plant
        )
    except ValueError as exc:  # refused: the scalar and the sync env must refuse it alike
        assert "RK4 substeps" in str(exc) and "1/s" in str(exc), str(exc)
        for make in (
            lambda: gym.make(env_id, plant=plant),
            lambda: gym.make_vec(env_id, 2, vectorization_mode="sync", plant=plant),
        ):
            with pytest.raises(ValueError, match="RK4 substeps"):
                make()
        event("refused at construction")
        return 0
    sync = gym.make_vec(
        env_id, 2, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, plant=plant
    )
    scalar = gym.make(env_id, plant=plant, disable_env_checker=True)
    task = native.unwrapped.task if hasattr(native, "unwrapped") else native.task
    work = task.substeps * getattr(task, "rk4_substeps", 1)
    steps = int(min(300, max(20, RK4_BUDGET // work)))
    event(f"ran {'300' if steps == 300 else '20-299'} steps")
    rng = np.random.default_rng(seed)
    a, b = native.reset(seed=seed), sync.reset(seed=seed)
    _assert_same(a, b, "reset")
    obs0, _ = scalar.reset(seed=seed)
    assert np.array_equal(obs0, a[0][0])
    scalar_done = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's overflow notes where a plant diverges
        for k in range(steps):
            actions = rng.uniform(-1.0, 1.0, (2, 1)).astype(np.float32)
            ra, rb = native.step(actions), sync.step(actions)
            _check_step(ra, f"native step {k}")
            for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), ra, rb, strict=True):
                _assert_same(x, y, f"{name} at step {k}")
            # stronger than the documented contract: the substep rule keeps the state finite, so
            # the guard never fires here (it does where the rule is broken, see the mutation
            # note in the module docs)
            assert "nonfinite" not in ra[4] and "nonfinite" not in ra[4].get("final_info", {}), k
            if mode == AutoresetMode.NEXT_STEP:  # the scalar env, as sub-env 0 of SyncVectorEnv
                if scalar_done:
                    obs, _ = scalar.reset()
                    assert np.array_equal(obs, ra[0][0])
                    scalar_done = False
                    continue
                obs, reward, terminated, truncated, info = scalar.step(actions[0])
                assert np.array_equal(obs, ra[0][0]) and reward == ra[1][0]
                assert (terminated, truncated) == (ra[2][0], ra[3][0])
                assert info == (
                    {"nonfinite": True} if "nonfinite" in ra[4] and ra[4]["_nonfinite"][0] else {}
                )
                scalar_done = terminated or truncated
    return steps


@pytest.mark.slow
@SETTINGS
@given(plant=plants(), mode=st.sampled_from([AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]))
def test_nozzle_envs_stay_finite_or_refuse_the_plant(plant, mode):
    _run_against_sync(NOZZLE, plant, mode, seed=3)


@SETTINGS
@given(plant=plants(), mode=st.sampled_from([AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]))
def test_launcher_envs_stay_finite_or_refuse_the_plant(plant, mode):
    _run_against_sync(LAUNCHER, plant, mode, seed=5)


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
@pytest.mark.parametrize("row", ["linear", "bouc_wen"])
def test_a_stiff_joint_is_refused_naming_the_damping_rate(env_id, row):
    """J = 1e-6 with Table 1's b and k: b/J = 4e8 1/s, which no RK4 step under 10,000 per sample
    keeps stable (the env used to return NaN forever)."""
    plant = NozzleParameters(**{**published_nozzle(row).to_dict(), "J": 1e-6})
    for make in (
        lambda: gym.make(env_id, plant=plant),
        lambda: gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", plant=plant),
        lambda: gym.make_vec(env_id, 2, vectorization_mode="sync", plant=plant),
    ):
        with pytest.raises(ValueError, match=r"damping rate b/J = .* 1/s \(b = .*, J = 1e-06 kg m\^2\)"):
            make()


def test_a_damping_limited_plant_that_diverged_now_runs_finite():
    """J = 1e-3 with Table 1's linear b and k: the accuracy rule alone (the old rule) gives 383
    substeps, where h b/J = 7.9 is beyond RK4's real-axis limit and the motion diverges; the
    stability rule takes 2316 and the env runs finite."""
    plant = NozzleParameters.linear(1e-3, 376.53, 1.43e5)
    old = recommended_substeps(plant, 0.008, ENVELOPE, nozzle_plants.ENV_STEP_RATE)
    assert 0.008 / old * plant.b / plant.J > RK4_REAL_AXIS_LIMIT
    with np.errstate(all="ignore"):
        diverged = simulate_nozzle(plant, np.full(20, 1e-3), substeps=old)
    assert not np.all(np.isfinite(diverged))
    task = NozzleTask.build(plant=plant)
    assert 0.008 / task.substeps * plant.b / plant.J <= STABLE_STEP_RATE
    env = gym.make(NOZZLE, plant=plant)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1e-3, 1e-3, 1).astype(np.float32))
        assert np.all(np.isfinite(obs)) and math.isfinite(reward) and info == {}
        if terminated or truncated:
            env.reset()


def _rk4_gain(z: np.ndarray) -> np.ndarray:
    return np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(
    j=_log_uniform(1e-8, 1e3), b=st.one_of(st.just(0.0), _log_uniform(1e-3, 1e8)), k=_log_uniform(1e-3, 1e10)
)
def test_the_rule_puts_the_linear_joint_inside_rk4s_stability_region(j, b, k):
    """Independently of the rule's rates: the eigenvalues of the linear joint times the step the
    env takes lie where RK4 does not amplify; a refused plant needed more than MAX_SUBSTEPS."""
    plant = NozzleParameters.linear(j, b, k)
    eig = np.linalg.eigvals(np.array([[0.0, 1.0], [-k / j, -b / j]]))
    try:
        substeps = NozzleTask.build(plant=plant).substeps
    except ValueError as exc:
        assert "RK4 substeps" in str(exc)
        needed = 0.008 * max(np.max(np.abs(eig)) / RK4_REAL_AXIS_LIMIT, math.sqrt(k / j) / 0.25)
        assert needed > MAX_SUBSTEPS / 5, (needed, str(exc))  # refused for a need of the same order
        return
    assert substeps <= MAX_SUBSTEPS
    assert np.all(_rk4_gain(0.008 / substeps * eig) <= 1.0 + 1e-12)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(plant=plants())
def test_every_rate_times_the_step_is_within_the_stability_bound(plant):
    """The counts of both envs keep h * rate <= STABLE_STEP_RATE for every rate of the joint,
    for the nozzle at its 8 ms step and the launcher at its 2 ms servo sample."""
    for build, dt, steps in (
        (lambda: NozzleTask.build(plant=plant), 0.008, lambda task: task.substeps),
        (lambda: LauncherTask.build_launcher(plant=plant), 0.002, lambda task: task.rk4_substeps),
    ):
        try:
            task = build()
        except ValueError as exc:
            assert "RK4 substeps" in str(exc) and "1/s" in str(exc)
            continue
        h = dt / steps(task)
        for rate in stiff_rates(plant, ENVELOPE, TORQUE, dt):
            assert h * rate.rate <= STABLE_STEP_RATE * (1 + 1e-12), rate


def test_default_plants_keep_their_substeps():
    """Table 1's joints and the identified one: the accuracy rule still sets the counts (3 per
    nozzle step, 1 per launcher servo sample), so their trajectories keep every bit."""
    for plant in ("bouc_wen", "linear", "identified"):
        assert NozzleTask.build(plant=plant).substeps == 3
        assert LauncherTask.build_launcher(plant=plant).rk4_substeps == 1


def test_explicit_substeps_below_the_stability_bound_are_refused():
    plant = NozzleParameters.linear(1e-3, 376.53, 1.43e5)
    with pytest.raises(ValueError, match=r"substeps=400 is too few .* damping rate b/J"):
        gym.make(NOZZLE, plant=plant, substeps=400)
    assert NozzleTask.build(plant=plant, substeps=3000).substeps == 3000
    with pytest.raises(ValueError, match="substeps must be an integer in 1-10000"):
        gym.make(NOZZLE, substeps=MAX_SUBSTEPS + 1)


# --- the non-finite guard, forced by an integrator that poisons the state above a torque


def _poisoned(monkeypatch: pytest.MonkeyPatch, threshold: float) -> None:
    """Make the env integrators return NaN wherever |torque| > threshold (a deterministic
    function of the torque, so the scalar and the batched envs poison the same steps)."""
    real_floats, real_arrays = nozzle_task.rk4_floats, nozzle_task.rk4_arrays

    def floats(x, v, w, tau, h, steps, p):
        out = real_floats(x, v, w, tau, h, steps, p)
        return (math.nan, math.nan, math.nan) if abs(tau) > threshold else out

    def arrays(state, tau, h, steps, p, skip=None):
        real_arrays(state, tau, h, steps, p, skip)
        state[:, np.abs(np.broadcast_to(tau, state.shape[1:])) > threshold] = np.nan

    monkeypatch.setattr(nozzle_task, "rk4_floats", floats)
    monkeypatch.setattr(nozzle_task, "rk4_arrays", arrays)


@pytest.mark.parametrize(("env_id", "threshold"), [(NOZZLE, 0.9 * TORQUE), (LAUNCHER, 6.0e3)])
def test_a_nonfinite_state_ends_the_episode_with_the_flag(monkeypatch, env_id, threshold):
    _poisoned(monkeypatch, threshold)
    env = gym.make(env_id, disable_env_checker=True)
    env.reset(seed=0)
    task = env.unwrapped.task
    flagged = 0
    for _ in range(40):
        env.reset()
        for t in range(1, task.horizon + 1):
            with np.errstate(invalid="ignore"):
                obs, reward, terminated, truncated, info = env.step(np.array([1.0], dtype=np.float32))
            assert np.all(np.isfinite(obs)) and math.isfinite(reward)
            if info:
                assert info == {"nonfinite": True} and terminated
                assert reward == task.nonfinite_reward(t) == -task.step_cost_bound * (task.horizon - t + 2)
                assert obs[0] == 0.0  # the NaN angle reads 0
                with pytest.raises(EpisodeOverError):
                    env.step(np.array([0.0], dtype=np.float32))
                flagged += 1
                break
            if terminated or truncated:
                break
        if flagged:
            break
    assert flagged


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
@pytest.mark.parametrize(("env_id", "threshold"), [(NOZZLE, 0.9 * TORQUE), (LAUNCHER, 6.0e3)])
def test_the_flag_is_the_same_in_the_native_vector_env_and_sync_vector_env(
    monkeypatch, env_id, threshold, mode
):
    _poisoned(monkeypatch, threshold)
    native = gym.make_vec(env_id, 4, vectorization_mode="vector_entry_point", autoreset_mode=mode)
    sync = gym.make_vec(env_id, 4, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode})
    _assert_same(native.reset(seed=7), sync.reset(seed=7), "reset")
    rng = np.random.default_rng(1)
    flags = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for k in range(300):
            actions = rng.uniform(-1.0, 1.0, (4, 1)).astype(np.float32)
            ra, rb = native.step(actions), sync.step(actions)
            _check_step(ra, f"step {k}")
            for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), ra, rb, strict=True):
                _assert_same(x, y, f"{name} at step {k}")
            info = ra[4].get("final_info", {}) if mode == AutoresetMode.SAME_STEP else ra[4]
            flags += int(info.get("_nonfinite", np.zeros(1, bool)).sum())
            if mode == AutoresetMode.DISABLED and (ra[2] | ra[3]).any():
                mask = ra[2] | ra[3]
                _assert_same(
                    native.reset(options={"reset_mask": mask}),
                    sync.reset(options={"reset_mask": mask}),
                    f"partial reset at step {k}",
                )
    assert flags >= 3


# --- the loader: non-physical plants are refused, naming the field

GOOD = published_nozzle("bouc_wen").to_dict()
BAD_VALUES = {
    "J": [0.0, -1.0, math.nan, math.inf],
    "k": [0.0, -1.0e5, math.inf],
    "b": [-1.0, math.nan, -math.inf],
    "a": [-0.1, 1.5, math.nan],
    "A": [0.0, -0.35],
    "n": [0.0, -1.0, math.inf],
    "gamma": [-0.5, math.nan],
    "beta": [-5.0, math.inf],
}


@settings(max_examples=60, deadline=None, derandomize=True)
@given(data=st.data())
def test_the_loader_refuses_non_physical_joints_naming_the_field(data, tmp_path_factory):
    field = data.draw(st.sampled_from(sorted(BAD_VALUES)))
    value = data.draw(st.sampled_from(BAD_VALUES[field]))
    name = "beta \\+ gamma" if field == "beta" and math.isfinite(value) else field
    with pytest.raises(ValueError, match=name):
        NozzleParameters(**{**GOOD, field: value})
    doc = identified_nozzle().to_dict()
    doc["bouc_wen"][field] = value
    path = tmp_path_factory.mktemp("model") / "model.json"
    path.write_text(json.dumps(doc))  # NaN and inf as JSON's NaN / Infinity, which Python reads back
    with pytest.raises(ValueError, match=name):
        NozzleModel.load(path)
    if field in ("J", "b", "k"):
        doc = identified_nozzle().to_dict()
        doc["linear"][field] = value
        path.write_text(json.dumps(doc))
        with pytest.raises(ValueError, match=f"linear.{field}"):
            NozzleModel.load(path)


def test_the_loader_refuses_booleans_and_an_overflowing_normalization():
    with pytest.raises(ValueError, match="nozzle parameter J must be a finite number"):
        NozzleParameters(**{**GOOD, "J": True})
    with pytest.raises(ValueError, match="not finite"):
        NozzleParameters(**{**GOOD, "A": 1e3, "n": 200.0})  # A^(n - 1) = 1e597


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
def test_the_largest_bouc_wen_exponent_steps_finitely_and_a_larger_is_refused(env_id):
    """At n = MAX_N a random-action run stays finite (at n = 1e22 every step was non-finite); above
    it the joint is refused, naming n."""
    assert MAX_N >= 20  # the literature's exponents, and the fits' 1-2, are taken
    steepest = NozzleParameters(**{**GOOD, "n": MAX_N})
    env = gym.make(env_id, plant=steepest)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(200):
        _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, size=1).astype(np.float32))
        assert np.isfinite(reward) and not info.get("nonfinite", False)
        if terminated or truncated:
            env.reset()
    for n in (np.nextafter(MAX_N, np.inf), 1e22):
        with pytest.raises(ValueError, match=r"nozzle parameter n must be at most 1000, got"):
            NozzleParameters(**{**GOOD, "n": n})


# --- engines: an unstable identified model is refused


def _scaled_engine(scale: float) -> AlphaCanonicalModel:
    """The identified 100 % model with its output-injection columns scaled (spectral radius
    0.58 at scale 1, 2.4 at 3, 1e200 at 1e200)."""
    model = identified_model(100)
    a = model.A.copy()
    a[:, a.shape[0] - 2 :] *= scale
    return AlphaCanonicalModel(
        A=a,
        B=model.B,
        C=model.C,
        dt=model.dt,
        observability_indices=model.observability_indices,
        lam=model.lam,
    )


@pytest.mark.parametrize("scale", [3.0, 1e200])
def test_unstable_engine_plants_are_refused(scale, tmp_path):
    model = _scaled_engine(scale)
    assert model.spectral_radius() > 1
    path = tmp_path / "unstable.json"
    model.save(path)
    for plant in (model, str(path)):
        for make in (
            lambda plant=plant: gym.make(ENGINE, plant=plant),
            lambda plant=plant: gym.make_vec(ENGINE, 2, vectorization_mode="vector_entry_point", plant=plant),
        ):
            with pytest.raises(ValueError, match=r"spectral radius .* >= 1"):
                make()
    gym.make(ENGINE, plant=_scaled_engine(1.0)).reset(seed=0)  # the stable one still loads


# --- plant files the envs are given by path: a bad type is a ValueError naming the file and key


@pytest.mark.parametrize(
    ("env_id", "where", "value", "message"),
    [
        (ENGINE, "lambda", {"a": 1}, "not an engine model: lambda must be a list of 2 finite gains"),
        (ENGINE, "dt", 10**400, "not an engine model: dt must be a positive number of seconds, got an int"),
        (NOZZLE, "bouc_wen.J", 10**400, "nozzle parameter J must be a finite number, got an integer"),
        (NOZZLE, "linear.A", [[10**400] * 4] * 4, "linear.A must be a numeric matrix .*integer too large"),
    ],
    ids=["engine-lambda-object", "engine-dt-bigint", "nozzle-bw-J-bigint", "nozzle-lin-A-bigint"],
)
def test_badly_typed_plant_files_are_value_errors_naming_file_and_key(
    tmp_path, env_id, where, value, message
):
    doc = (identified_model(100) if env_id == ENGINE else identified_nozzle()).to_dict()
    *section, key = where.split(".")
    (doc[section[0]] if section else doc)[key] = value
    path = tmp_path / "plant.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=re.escape(f"{path}: ") + message):
        gym.make(env_id, plant=str(path))


@pytest.mark.parametrize("env_id", [ENGINE, NOZZLE])
def test_a_deeply_nested_plant_file_is_a_value_error_naming_it(tmp_path, env_id):
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match=re.escape(f"{path}: nested too deeply to read as JSON")):
        gym.make(env_id, plant=str(path))


def test_substeps_take_numpy_integers_as_the_other_integer_options_do():
    """np.int64(4) was refused ('must be an integer') where every other numeric option takes
    numpy scalars; it now steps as the int 4 does, bit for bit; numpy booleans and floats stay
    refused."""
    numpy_count, plain = gym.make(NOZZLE, substeps=np.int64(4)), gym.make(NOZZLE, substeps=4)
    assert numpy_count.unwrapped.task.substeps == 4 and type(numpy_count.unwrapped.task.substeps) is int
    numpy_count.reset(seed=1)
    plain.reset(seed=1)
    for action in 0.05 * np.sin(np.arange(20)):  # small: the episode stays in its envelope
        a, b = numpy_count.step(np.array([action])), plain.step(np.array([action]))
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:3] == b[1:3]
    for bad in (np.bool_(True), np.float64(4.0), np.int64(0)):
        with pytest.raises(ValueError, match="substeps must be an integer in 1-10000"):
            gym.make(NOZZLE, substeps=bad)
