"""Bad input to the envs (options, model files, seeds, actions) raises ValueError or TypeError
naming the problem: never another exception type, an infinite reward or a silently wrong result."""

from __future__ import annotations

import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ssme_envs.models
from ssme_envs.envs.engine_throttle import power_profile
from ssme_envs.envs.faults import FAULT_KINDS, Fault
from ssme_envs.envs.inputs import batch_actions
from ssme_envs.models.engine import ENGINE_DT, TruthConfig
from ssme_envs.models.nozzle import NOZZLE_DT

TRACKING = "ssme_envs/EngineTracking-v0"
THROTTLE = "ssme_envs/EngineThrottle-v0"
NOZZLE = "ssme_envs/NozzleTVC-v0"
LAUNCHER = "ssme_envs/LauncherPitch-v0"
ENGINES = (TRACKING, THROTTLE)
DATA = Path(ssme_envs.models.__file__).parent / "data"
FEW = settings(max_examples=25, deadline=None)

huge_ints = st.integers(min_value=2**1024, max_value=10**400) | st.integers(
    min_value=-(10**400), max_value=-(2**1024)
)
not_numbers = st.sampled_from(["abc", "1", b"1", None, [1.0], {"a": 1}, 1 + 0j, object(), True, False])


def vector(env_id: str, num_envs: int = 2, **options) -> gym.vector.VectorEnv:
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **options)


def engine_model_file(tmp_path: Path, dt: float) -> Path:
    """The packaged identified engine model.json with its sample time replaced."""
    model = json.loads((DATA / "engine_identified_100.json").read_text())
    model["dt"] = dt
    path = tmp_path / f"model_{dt!r}.json"
    path.write_text(json.dumps(model))
    return path


# 1. the truth's noise (and the valves' dead bands) within physical bounds


@FEW
@given(noise=st.floats(min_value=0.0501, max_value=1e308) | huge_ints | st.just(True))
def test_truth_sensor_noise_beyond_the_bound_is_refused(noise):
    for env_id in ENGINES:
        for truth in ({"sensor_noise": noise}, {"sensor_noise": [1e-4, noise]}):
            with pytest.raises(ValueError, match="truth sensor_noise"):
                gym.make(env_id, truth=truth)
    with pytest.raises(ValueError, match="truth sensor_noise"):
        vector(TRACKING, truth={"sensor_noise": noise})


def test_truth_noise_at_its_bound_gives_finite_rewards_and_a_config_is_checked_too():
    env = gym.make(TRACKING, truth={"sensor_noise": 0.05})
    env.reset(seed=0)
    for _ in range(5):
        _, reward, *_ = env.step(np.zeros(2))
        assert math.isfinite(reward)
    with pytest.raises(ValueError, match="truth sensor_noise"):
        gym.make(TRACKING, truth=TruthConfig(sensor_noise=1e154))
    for name in ("backlash", "stiction"):
        for width in (0.5, 1e308, 10**400):
            with pytest.raises(ValueError, match=f"truth {name}"):
                gym.make(TRACKING, truth={name: width})
    gym.make(TRACKING, truth={"backlash": np.float32(1e-3), "stiction": np.float64(1e-4)})


# 2. an engine model.json's sample time


@pytest.mark.parametrize("dt", [2.0, 1.0, 0.6, 1e-9, 5e-324])
def test_engine_model_with_an_unusable_dt_is_refused_when_built(tmp_path, dt):
    path = engine_model_file(tmp_path, dt)
    for make in (lambda: gym.make(TRACKING, plant=str(path)), lambda: vector(TRACKING, plant=str(path))):
        with pytest.raises(ValueError, match=r"plant dt must be within .* steps"):
            make()


def test_engine_model_dt_bounds_and_episode_steps(tmp_path):
    fine = gym.make(TRACKING, plant=str(engine_model_file(tmp_path, 0.5))).unwrapped
    assert fine.task.horizon == 20
    fine.reset(seed=0)
    fine.step(np.zeros(2))
    assert gym.make(TRACKING, plant=str(engine_model_file(tmp_path, 0.001))).unwrapped.task.horizon == 10_000
    with pytest.raises(ValueError, match=r"at most 1000000 steps, got dt=0.001 s for 3600 s"):
        gym.make(TRACKING, plant=str(engine_model_file(tmp_path, 0.001)), episode_seconds=3600.0)


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
def test_a_nozzle_model_files_dt_never_reaches_the_env(tmp_path, env_id):
    model = json.loads((DATA / "nozzle_identified.json").read_text())
    for dt in (5.0, 1e-9):
        model["linear"]["dt"] = dt
        path = tmp_path / "nozzle.json"
        path.write_text(json.dumps(model))
        env = gym.make(env_id, plant=str(path)).unwrapped
        reference = gym.make(env_id, plant=str(DATA / "nozzle_identified.json")).unwrapped
        assert env.task.dt == reference.task.dt and env.task.horizon == reference.task.horizon
    assert gym.make(NOZZLE, plant=str(path)).unwrapped.task.dt == NOZZLE_DT


# 3. seeds


@FEW
@given(seed=st.integers(max_value=-1))
def test_negative_seeds_are_value_errors(seed):
    env = gym.make(TRACKING).unwrapped
    with pytest.raises(ValueError, match="Seed must be greater or equal to zero"):
        env.reset(seed=seed)
    venv = vector(TRACKING)
    for bad in (seed, [1, seed], [seed, None]):
        with pytest.raises(ValueError, match="Seed must be greater or equal to zero"):
            venv.reset(seed=bad)


@FEW
@given(
    seed=st.floats(allow_nan=True)
    | st.text(max_size=3)
    | st.sampled_from([True, False, np.bool_(True), b"1"])
)
def test_seeds_that_are_not_integers_are_type_errors(seed):
    env = gym.make(NOZZLE).unwrapped
    with pytest.raises(TypeError, match="Seed must be an integer"):
        env.reset(seed=seed)
    venv = vector(NOZZLE)
    for bad in (seed, [2, seed]):
        with pytest.raises(TypeError, match="Seed must be an integer"):
            venv.reset(seed=bad)


def test_seed_errors_are_still_gymnasiums_errors_for_callers_that_caught_those():
    env = gym.make(TRACKING).unwrapped
    for bad in (-1, "a", 1.5):
        with pytest.raises(gym.error.Error):
            env.reset(seed=bad)


def test_a_bad_seed_in_a_list_reseeds_no_sub_env():
    venv = vector(TRACKING, num_envs=3)
    venv.reset(seed=7)
    seeds, states = venv.np_random_seed, [rng.bit_generator.state for rng in venv.np_random]
    for bad in ([1, 2, -1], [1, 2, "a"], [1, True, 3]):
        with pytest.raises((TypeError, ValueError)):
            venv.reset(seed=bad)
    assert venv.np_random_seed == seeds
    assert [rng.bit_generator.state for rng in venv.np_random] == states


def test_numpy_integer_seeds_are_accepted_as_ints():
    a, b = gym.make(TRACKING).unwrapped, gym.make(TRACKING).unwrapped
    np.testing.assert_array_equal(a.reset(seed=np.int64(3))[0], b.reset(seed=3)[0])
    assert a.np_random_seed == 3
    va, vb = vector(TRACKING), vector(TRACKING)
    np.testing.assert_array_equal(va.reset(seed=np.uint32(5))[0], vb.reset(seed=5)[0])
    np.testing.assert_array_equal(va.reset(seed=np.array([8, 9]))[0], vb.reset(seed=[8, 9])[0])
    assert va.np_random_seed == (8, 9)


# 4. numbers too large for a float


@pytest.mark.parametrize(
    ("env_id", "name"),
    [
        (TRACKING, "power"),
        (TRACKING, "reference_amplitude"),
        (TRACKING, "episode_seconds"),
        (TRACKING, "action_scale"),
        (NOZZLE, "episode_seconds"),
        (NOZZLE, "sensor_noise"),
        (NOZZLE, "actuator_lag"),
        (NOZZLE, "rate_limit"),
        (NOZZLE, "plant_spread"),
        (NOZZLE, "reference_amplitude_deg"),
        (NOZZLE, "uncertainty_scale"),
        (LAUNCHER, "instability"),
        (LAUNCHER, "effectiveness"),
        (LAUNCHER, "sensor_noise"),
    ],
)
@FEW
@given(value=huge_ints)
def test_ints_too_large_for_a_float_are_value_errors_naming_the_option(env_id, name, value):
    with pytest.raises(ValueError, match=name):
        gym.make(env_id, **{name: value})


@pytest.mark.parametrize("env_id", [TRACKING, THROTTLE, NOZZLE, LAUNCHER])
@FEW
@given(time=st.floats(min_value=3600.5, allow_infinity=True) | huge_ints | st.just(math.nan))
def test_fault_times_far_beyond_any_episode_are_value_errors(env_id, time):
    with pytest.raises(ValueError, match="fault time"):
        gym.make(env_id, fault={"kind": "sensor_bias", "time": time})


@FEW
@given(value=huge_ints, index=st.integers(0, 1))
def test_actions_too_large_for_a_float_are_value_errors(value, index):
    env = gym.make(TRACKING).unwrapped
    env.reset(seed=0)
    action = [0, 0]
    action[index] = value
    with pytest.raises(ValueError, match="too large for a float"):
        env.step(action)
    env.step([0, 0])  # nothing changed: the episode goes on
    venv = vector(TRACKING)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="too large for a float"):
        venv.step([action, [0, 0]])


# 5. actions that are not real numbers

WRONG_ACTIONS = [
    {0: 0.3, 1: -0.5},
    b"ab",
    "ab",
    np.array(["1", "0"]),
    ["1", "0"],
    {0.1, 0.2},
    range(2),
    np.array([True, False]),
    [True, False],
    [np.bool_(True), 0.0],
    np.array([1 + 0j, 0]),
    [1 + 0j, 0.0],
    [None, 0.0],
    np.array([0.1, 0.2], dtype=object),
    iter([0.1, 0.2]),
]


@FEW
@given(action=st.sampled_from(WRONG_ACTIONS))
def test_the_scalar_env_refuses_actions_that_are_not_real_numbers(action):
    env = gym.make(TRACKING).unwrapped
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"action must be 2 numbers \(OPOV, FPOV\)"):
        env.step(action)


@FEW
@given(
    action=st.sampled_from(
        [
            np.full((2, 2), 0.5 + 1j),
            np.full((2, 2), 0.5 + 0j),
            np.ones((2, 2), bool),
            [["1", "0"], ["0", "0"]],
            {0: [0.1, 0.2]},
            np.full((2, 2), "0.5"),
            [[None, 0.0], [0.0, 0.0]],
            [[True, 0.5], [0.0, 0.0]],
            [(0.1, 0.2), [np.bool_(False), 0.0]],
            [np.array([0.1, 0.2]), np.array([True, False])],
        ]
    )
)
def test_the_vector_env_refuses_actions_that_are_not_real_numbers(action):
    venv = vector(TRACKING)
    venv.reset(seed=0)
    with pytest.raises(TypeError, match="actions must be real numbers"):
        venv.step(action)


@FEW
@given(values=st.lists(st.floats(-2.0, 2.0) | st.integers(-2, 2), min_size=2, max_size=2))
def test_real_numbers_in_any_accepted_form_act_as_the_float_array(values):
    forms = [
        list(values),
        tuple(values),
        [np.float32(v) if isinstance(v, float) else np.int64(v) for v in values],
        np.array(values, dtype=np.float64),
    ]
    if all(isinstance(v, int) for v in values):
        forms.append(np.array(values, dtype=np.int32))
    for action in forms:
        env = gym.make(TRACKING).unwrapped
        env.reset(seed=1)
        obs, reward, *_ = env.step(action)
        reference = gym.make(TRACKING).unwrapped
        reference.reset(seed=1)
        want = np.array([float(np.float32(v)) if isinstance(v, np.float32) else float(v) for v in action])
        expected = reference.step(want)
        np.testing.assert_array_equal(obs, expected[0])
        assert reward == expected[1]


# 6. bools are not numbers; numpy numbers are


@pytest.mark.parametrize(
    ("env_id", "options", "message"),
    [
        (TRACKING, {"episode_seconds": True}, "episode_seconds"),
        (TRACKING, {"reference_amplitude": False}, "reference_amplitude"),
        (TRACKING, {"reference_amplitude": [0.01, True]}, "reference_amplitude"),
        (TRACKING, {"truth": {"sensor_noise": True}}, "sensor_noise"),
        (TRACKING, {"fault": {"kind": "sensor_bias", "time": True}}, "fault time"),
        (TRACKING, {"fault": {"kind": "sensor_bias", "time": 1.0, "index": True}}, "fault index"),
        (TRACKING, {"fault": {"kind": "gain_loss", "time": 1.0, "magnitude": True}}, "fault magnitude"),
        (THROTTLE, {"fault": {"kind": "stuck_valve", "time": 1.0, "index": np.bool_(False)}}, "fault index"),
        (NOZZLE, {"episode_seconds": True}, "episode_seconds"),
        (NOZZLE, {"sensor_noise": False}, "sensor_noise"),
        (LAUNCHER, {"instability": True}, "instability"),
    ],
)
def test_bools_are_refused_where_a_number_is_expected(env_id, options, message):
    with pytest.raises(ValueError, match=message):
        gym.make(env_id, **options)


def test_bool_num_envs_and_time_limits_are_refused():
    for options in ({"num_envs": True}, {"num_envs": 2, "max_episode_steps": True}):
        with pytest.raises(ValueError, match="must be a positive integer"):
            gym.make_vec(TRACKING, vectorization_mode="vector_entry_point", **options)


@pytest.mark.parametrize(
    ("profile", "message"),
    [
        ([(0.0, 100.0), (1e7, 100.0)], "profile must end within 3600 s"),
        ([(0.0, 100.0), (10**400, 100.0)], "profile time must be finite, got an integer of about 401 digits"),
        ([(0.0, 100.0), ("a", 100.0)], "at least two"),
    ],
)
def test_a_throttle_profile_is_checked_before_its_table_is_built(profile, message):
    """1e7 s once built a 3.9 GB table before the episode length was checked."""
    with pytest.raises(ValueError, match=message):
        gym.make(THROTTLE, profile=profile)


@pytest.mark.parametrize(("b_scale", "lam"), [(1e300, None), (1e4, None), (1.0, 1e308)])
def test_an_engine_plant_whose_outputs_would_overflow_is_refused(b_scale, lam):
    """B x 1e300 gave -inf rewards and NaN costs with exit 0; the refusal's bound is checked
    against a brute-force peak: a full-travel valve step held on the scaled model."""
    import dataclasses

    from ssme_envs.models.engine import MAX_PEAK_OUTPUT, published_model

    base = published_model(100)
    model = dataclasses.replace(
        base, B=base.B * b_scale, lam=base.lam if lam is None else np.array([lam, 1.0])
    )
    with np.errstate(over="ignore", invalid="ignore"):
        x, peak = np.zeros(base.A.shape[0]), 0.0
        for _ in range(200):  # a step of +1 on both valves through the gains
            x = model.A @ x + model.B @ (1.0 + np.abs(model.lam - 1.0))
            peak = max(peak, float(np.abs(model.C @ x).max()))
    assert not peak <= MAX_PEAK_OUTPUT  # the plant does reach beyond the bound
    with pytest.raises(ValueError, match="engine plant refused: a valve travel of 1 can drive"):
        gym.make(TRACKING, plant=model)


def test_the_packaged_engine_plants_pass_the_gain_check():
    for power in (70.0, 80.0, 90.0, 100.0):
        for plant in ("truth", "identified"):
            gym.make(TRACKING, plant=plant, power=power).reset(seed=0)


def test_the_ssme_models_reach_below_five_under_any_full_valve_travel():
    """The figure the refusal quotes: for each Table I model and output, the worst +-1 valve
    sequence (each valve against the sign of its impulse response, through eq 36's gains),
    simulated by scipy.signal.dlsim, peaks below 5 (normalized) and within the check's bound."""
    import scipy.signal

    from ssme_envs.models.engine import MAX_PEAK_OUTPUT, POWER_LEVELS, published_model

    steps = 400
    for power in POWER_LEVELS:
        model = published_model(power)
        system = (model.A, model.B, model.C, np.zeros((2, 2)), model.dt)
        _, impulse = scipy.signal.dimpulse(system, n=steps)  # per input: (steps, outputs)
        for i in range(2):
            signs = np.stack([np.sign(impulse[j][::-1, i]) for j in range(2)], axis=1)  # u(k) vs h(N-1-k)
            u_star = signs + (model.lam - 1.0) * np.abs(signs)
            _, y, _ = scipy.signal.dlsim(system, u_star)
            assert 1.0 < abs(y[-1, i]) < 5.0 <= MAX_PEAK_OUTPUT, (power, i)


def test_a_plant_of_its_own_is_its_truth_design_and_a_design_at_another_dt_is_refused():
    """An engine plant at dt 0.2 s ran the 0.04 s designs with exit 0."""
    import dataclasses

    from agents import parse_controller
    from ssme_envs.models.engine import published_model

    slow = dataclasses.replace(published_model(90), dt=0.2)
    env = gym.make(TRACKING, plant=slow)
    assert env.unwrapped.task.design_model("truth") is slow
    with pytest.raises(ValueError, match=r"identified design model has dt 0.04 s but the env's plant 0.2 s"):
        env.unwrapped.task.design_model("identified")
    venv = vector(TRACKING, plant=slow)
    assert parse_controller("lqi:truth", TRACKING)(venv) is not None
    with pytest.raises(ValueError, match="design on 'truth'"):
        parse_controller("lqi", TRACKING)(venv)


def test_numpy_integer_counts_are_counts():
    venv = gym.make_vec(TRACKING, num_envs=np.int64(3), vectorization_mode="vector_entry_point")
    assert venv.num_envs == 3 and type(venv.num_envs) is int
    venv.reset(seed=0)
    assert venv.step(np.zeros((3, 2), np.float32))[0].shape == (3, 10)


@pytest.mark.parametrize("env_id", [TRACKING, NOZZLE])
def test_a_vector_env_too_large_for_memory_is_refused_before_it_is_built(env_id, monkeypatch):
    """The estimate is its own arithmetic over the task's tables; against it, a limit of 1 GB
    refuses 10**9 envs (and names the most that fit) and lets 4 pass."""
    import ssme_envs.cli_checks as checks

    monkeypatch.setattr(checks, "available_memory", lambda: 10**9)
    with pytest.raises(ValueError, match=r"num_envs 1000000000 needs about .* use at most \d+"):
        gym.make_vec(env_id, num_envs=10**9, vectorization_mode="vector_entry_point")
    assert gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point").num_envs == 4


def _peak_bytes(env_id: str, num_envs: int) -> int:
    """tracemalloc's peak over resetting and stepping a vector env through a whole episode and
    on (zero actions, random ones every 50th step, so that some episodes restart beside others),
    above the memory before it was made: its tables and what its steps add, not the transients
    of building its task, which are the same for any number of sub-envs."""
    import gc
    import tracemalloc

    gc.collect()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
        tracemalloc.reset_peak()
        venv.reset(seed=0)
        rng = np.random.default_rng(0)
        for k in range(venv.unwrapped.task.horizon + 20):
            action = rng.uniform(-1.0, 1.0, venv.action_space.shape) if k % 50 == 49 else 0.0
            venv.step(np.broadcast_to(action, venv.action_space.shape).astype(np.float32))
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("env_id", [TRACKING, THROTTLE, NOZZLE, LAUNCHER])
def test_the_vector_memory_estimate_bounds_what_a_sub_env_allocates(env_id):
    """The bytes per sub-env that the memory check counts (episode_bytes and SUB_ENV_BYTES)
    against numpy's allocations as tracemalloc traces them: the slope of the peak between 64 and
    320 sub-envs (what each sub-env adds, without the fixed costs) is at most the estimate, and
    the estimate at most 6 times it, so that the check refuses no vector env that would fit by
    much (it counted the episode tables of the nozzle's streams, about 30 times too many)."""
    from ssme_envs.envs.episode_streams import episode_bytes
    from ssme_envs.envs.inputs import SUB_ENV_BYTES

    # first: what a first make caches (the throttle's linked model) is in neither measurement
    task = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point").unwrapped.task
    estimate = episode_bytes(task) + SUB_ENV_BYTES
    measured = (_peak_bytes(env_id, 320) - _peak_bytes(env_id, 64)) / 256
    assert measured <= estimate <= 6 * measured, (measured, estimate)


@pytest.mark.parametrize(
    ("env_id", "options", "plain"),
    [
        (NOZZLE, {"sensor_noise": np.float32(2e-4)}, {"sensor_noise": float(np.float32(2e-4))}),
        (NOZZLE, {"episode_seconds": np.int64(2)}, {"episode_seconds": 2}),
        (NOZZLE, {"plant_spread": np.float64(0.1)}, {"plant_spread": 0.1}),
        (NOZZLE, {"uncertainty_scale": np.float32(2.0)}, {"uncertainty_scale": 2.0}),
        (LAUNCHER, {"instability": np.float64(4.0)}, {"instability": 4.0}),
        (
            TRACKING,
            {"power": np.float32(90.0), "episode_seconds": np.int64(3)},
            {"power": 90.0, "episode_seconds": 3},
        ),
        (TRACKING, {"reference_amplitude": np.array([0.01, 0.02])}, {"reference_amplitude": (0.01, 0.02)}),
        (
            TRACKING,
            {
                "fault": {
                    "kind": "gain_loss",
                    "time": np.float32(1.0),
                    "index": np.int64(1),
                    "magnitude": np.float64(0.5),
                }
            },
            {"fault": {"kind": "gain_loss", "time": 1.0, "index": 1, "magnitude": 0.5}},
        ),
    ],
)
def test_numpy_numbers_are_accepted_as_python_numbers(env_id, options, plain):
    env, same = gym.make(env_id, **options).unwrapped, gym.make(env_id, **plain).unwrapped
    assert env.task.horizon == same.task.horizon
    for e in (env, same):
        e.reset(seed=4)
    for _ in range(3):
        action = np.full(env.action_space.shape, 0.3)
        a, b = env.step(action), same.step(action)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4]


# 7. uncertainty_scale is checked whether the spread uses it or not


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
@FEW
@given(
    scale=not_numbers
    | st.floats().filter(lambda s: not 0 < s <= 100)
    | st.integers(max_value=0)
    | st.integers(min_value=101),
    spread=st.sampled_from([None, 0.0, 0.1]),
)
def test_uncertainty_scale_is_always_checked(env_id, scale, spread):
    with pytest.raises(ValueError, match="uncertainty_scale"):
        gym.make(env_id, uncertainty_scale=scale, plant_spread=spread)


# 8. dict options with keys of any type, fault kinds, profile entries, masked actions

FAULT_KEYS = ("kind", "time", "index", "magnitude")
TRUTH_KEYS = tuple(TruthConfig.__dataclass_fields__)
odd_keys = st.sampled_from([1, 2.5, None, (1, 2), b"kind", frozenset(), np.int64(3), np.str_("tim")])


@FEW
@given(
    keys=st.lists(
        odd_keys | st.text(max_size=6).filter(lambda key: key not in FAULT_KEYS + TRUTH_KEYS),
        min_size=1,
        max_size=3,
        unique_by=repr,
    )
)
def test_dict_options_name_their_unknown_keys_of_any_type(keys):
    """{1: 2} once failed joining the keys, {1: 2, "a": 3} sorting them: TypeErrors of neither."""
    extra = dict.fromkeys(keys, 2)
    for option, given_, noun in (
        ("fault", {"kind": "sensor_bias", "time": 1.0}, "key"),
        ("truth", {"backlash": 1e-4}, "option"),
    ):
        with pytest.raises(ValueError, match=rf"^{option}: unknown {noun}\(s\) ") as error:
            gym.make(TRACKING, **{option: {**given_, **extra}})
        message = str(error.value)
        assert all(repr(key) in message for key in extra), message
        assert "it takes 'kind', 'time'" in message if option == "fault" else "'backlash'" in message


@pytest.mark.parametrize("env_id", [TRACKING, THROTTLE, NOZZLE, LAUNCHER])
def test_every_env_names_a_fault_key_that_is_not_a_string(env_id):
    with pytest.raises(ValueError, match=r"^fault: unknown key\(s\) 1, 'a'; it takes 'kind'"):
        gym.make(env_id, fault={1: 2, "a": 3})


@pytest.mark.parametrize(
    "kind", [np.array(["gain_loss"]), np.array(["gain_loss", "x"]), ["gain_loss"], b"gain_loss", 1, None]
)
@pytest.mark.parametrize("env_id", [TRACKING, NOZZLE])
def test_a_fault_kind_that_is_not_a_str_is_refused_by_name(env_id, kind):
    """A 1-element array passed ``in FAULT_KINDS`` (elementwise ==) and failed as a dict key."""
    for fault in ({"kind": kind, "time": 1.0}, Fault(kind, 1.0)):
        with pytest.raises(ValueError, match=r"^fault kind must be a str, one of .*gain_loss; got "):
            gym.make(env_id, fault=fault)


def test_a_fault_kind_message_offers_only_the_kinds_the_env_takes():
    nozzle = ("sensor_bias", "gain_loss")
    for kind in ("stuck_valve", "explode"):
        with pytest.raises(
            ValueError, match=rf"^unknown fault kind '{kind}'; choose one of sensor_bias, gain_loss$"
        ):
            Fault.parse({"kind": kind, "time": 1.0}, 1, 1, kinds=nozzle)
        with pytest.raises(ValueError, match=f"choose one of {', '.join(FAULT_KINDS)}$"):
            Fault.parse({"kind": "explode", "time": 1.0}, 2, 2)
    assert Fault.parse({"kind": "gain_loss", "time": 1.0}, 1, 1, kinds=nozzle) == Fault(
        "gain_loss", 1.0, 0, 0.5
    )


@pytest.mark.parametrize("env_id", [NOZZLE, LAUNCHER])
def test_the_nozzle_envs_offer_only_their_fault_kinds(env_id):
    with pytest.raises(ValueError, match=r"choose one of sensor_bias, gain_loss$"):
        gym.make(env_id, fault={"kind": "explode", "time": 1.0})


@pytest.mark.parametrize(
    ("profile", "message"),
    [
        ([(False, 100.0), (True, 100.0)], "pairs of real numbers .*got bool False as the time of pair 0"),
        ([("0", "100"), ("5", "90")], "got str '0' as the time of pair 0"),
        ([(0.0, 100.0), (b"5", 90.0)], "got bytes b'5' as the time of pair 1"),
        ([(0.0, 100.0), (5.0, np.bool_(True))], "got bool np.True_ as the power of pair 1"),
        (np.array([[0.0, 100.0], [5.0, 90.0]]).astype(str), "got str '0.0' as the time of pair 0"),
        ([(0.0, 100.0), (5.0, None)], "got NoneType None as the power of pair 1"),
        ([(0.0, 100.0), (5.0, math.nan)], "power must be finite, got nan in pair 1"),
        ([(0.0, 100.0), (math.inf, 100.0)], "time must be finite, got inf in pair 1"),
        ([(0.0, 100.0), (5.0, 10**400)], "power must be finite, got an integer of about 401"),
    ],
)
def test_a_throttle_profile_entry_that_is_no_finite_real_number_is_named(profile, message):
    """Bools, strings and bytes once passed as numbers (np.asarray(dtype=float) reads them), and a
    NaN power was reported as times that do not increase."""
    with pytest.raises(ValueError, match=f"^profile.*{message}"):
        gym.make(THROTTLE, profile=profile)


@FEW
@given(
    steps=st.lists(
        st.tuples(st.floats(0.04, 5.0) | st.integers(1, 5), st.floats(65.0, 109.0) | st.integers(65, 109)),
        min_size=1,
        max_size=4,
    )
)
def test_a_valid_profile_gives_the_table_it_gave_before_in_any_real_form(steps):
    times = np.cumsum([0] + [step for step, _ in steps]).tolist()
    pairs = list(zip(times, [100] + [power for _, power in steps], strict=True))
    forms = [pairs, tuple(pairs), np.array(pairs), [np.array(pair) for pair in pairs]]
    forms.append([(np.float64(t), np.float32(p) if isinstance(p, float) else np.int64(p)) for t, p in pairs])
    for form in forms:
        points = np.asarray(form, dtype=float)  # what the profile was read as before its entries were checked
        expected = np.interp(np.arange(round(points[-1, 0] / ENGINE_DT) + 1) * ENGINE_DT, *points.T)
        np.testing.assert_array_equal(power_profile(form, ENGINE_DT), expected)


MASKED = [True, [False, True], [True, False]]


def test_a_masked_action_is_refused_unless_no_element_is_masked_then_it_is_its_data():
    """A masked element once reached float() as None (the scalar env) or its data (the vector env)."""
    env, same = gym.make(TRACKING).unwrapped, gym.make(TRACKING).unwrapped
    env.reset(seed=0)
    same.reset(seed=0)
    for mask in MASKED:
        for dtype in (np.float64, np.int64):
            with pytest.raises(
                ValueError, match=r"^action must be 2 numbers .*masked array with [12] masked"
            ):
                env.step(np.ma.masked_array(np.zeros(2, dtype), mask=mask))
    for action in (np.array([0.3, -0.2]), np.array([1, 0])):
        for form in (np.ma.masked_array(action, mask=False), np.ma.masked_array(action)):
            a, b = env.step(form), same.step(action.astype(float))
            np.testing.assert_array_equal(a[0], b[0])
            assert a[1:] == b[1:]
    venv = vector(TRACKING)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="masked array with 4 masked"):
        venv.step(np.ma.masked_array(np.zeros((2, 2), int), mask=True))
    for mask in MASKED:
        with pytest.raises(
            ValueError, match=r"^actions must be a float array .*masked array with [24] masked"
        ):
            batch_actions(np.ma.masked_array(np.zeros((2, 2)), mask=np.broadcast_to(mask, (2, 2))))
    action = np.array([[0.3, -0.2], [1.0, 0.0]])
    np.testing.assert_array_equal(batch_actions(np.ma.masked_array(action, mask=False)), action)


def test_the_vector_env_refuses_a_float_masked_action():
    venv = vector(TRACKING)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="masked array with 4 masked"):
        venv.step(np.ma.masked_array(np.zeros((2, 2)), mask=True))


@pytest.mark.parametrize(
    ("inputs", "outputs"),
    [
        (("beta_fpov", "beta_opov"), ("pc", "mr")),
        (("beta_opov", "beta_fpov"), ("mr", "pc")),
        (("a", "b"), ("x", "y")),
    ],
)
def test_an_engine_plant_of_other_channel_names_is_refused(tmp_path, inputs, outputs):
    """A model identified with --inputs beta_fpov,beta_opov was stepped with its valves swapped
    (the envs read channels by position): its DC gain, computed here from A, B and C, is the
    published model's with rows and columns exchanged, and the env took it with exit 0."""
    import dataclasses

    from ssme_envs.models.engine import published_model

    base = published_model(100)
    swapped = dataclasses.replace(base, input_names=inputs, output_names=outputs)
    gain = base.C @ np.linalg.solve(np.eye(base.A.shape[0]) - base.A, base.B)
    assert not np.allclose(gain, gain[::-1, ::-1])  # a swap would change the plant the env steps
    path = tmp_path / "model.json"
    swapped.save(path)
    for plant in (swapped, str(path)):
        with pytest.raises(ValueError, match=r"plant must map inputs \['beta_opov', 'beta_fpov'\] to"):
            gym.make(TRACKING, plant=plant)
    gym.make(TRACKING, plant=base).reset(seed=0)  # the names in their order: taken
