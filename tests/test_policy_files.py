"""Policies as data: safetensors + JSON, no pickle; crafted files run nothing and fail clearly."""

import base64
import contextlib
import hashlib
import json
import math
import os
import pickle
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import warnings
import zipfile
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import safetensors.torch
import stable_baselines3
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import parse_controller, policy_files
from agents.normalization import read_normalization, to_vec_normalize
from agents.policy_files import PICKLE_WARNING, load_policy, save_policy, write_atomic
from agents.policy_zip import _main as convert_main
from agents.sb3 import SHIPPED, PolicyController, load_trained, shipped_policy
from ssme_envs.cli import main
from ssme_envs.envs.sb3_adapter import make_sb3_vec_env

NOZZLE = "ssme_envs/NozzleTVC-v0"
REPO = Path(__file__).resolve().parents[1]
TRACKING = "ssme_envs/EngineTracking-v0"


class _Payload:
    """Unpickling this creates ``marker``: the stand-in for arbitrary code."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _malicious_zip(path: Path, marker: Path) -> Path:
    """An SB3-style zip whose ``data`` entry holds a serialized (pickled) object, as SB3 writes."""
    payload = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload}}
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", json.dumps(data))
        archive.writestr("pytorch_variables.pth", pickle.dumps(_Payload(marker)))
        archive.writestr("_stable_baselines3_version", stable_baselines3.__version__)
    return path


def _shipped_copy(tmp_path: Path, name: str = "NozzleTVC-v0") -> Path:
    env_id = "ssme_envs/" + name.removesuffix("-identified")
    source = shipped_policy(env_id, "identified" if name.endswith("-identified") else "truth")
    return Path(shutil.copytree(source, tmp_path / name))


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


@pytest.mark.filterwarnings("ignore:Detected pickle protocol")  # torch, on the crafted .pth
def test_a_crafted_sb3_zip_runs_nothing_unless_pickle_is_allowed(tmp_path, capsys):
    marker = tmp_path / "pwned"
    evil = _malicious_zip(tmp_path / "model.zip", marker)
    with pytest.raises(ValueError, match=r"can execute arbitrary code.*allow_pickle=True"):
        parse_controller(f"ppo:{evil}", NOZZLE)
    with pytest.raises(ValueError, match="refusing to load an SB3 zip"):
        PolicyController(evil, "ppo")
    args = ["evaluate", "--env", NOZZLE, "--controllers", f"ppo:{evil}", "--out", str(tmp_path / "e")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "arbitrary code" in err and "\n" not in err
    # a run directory holding only such a model.zip is not a policy: named, and not unpickled
    run = tmp_path / "old_run"
    run.mkdir()
    shutil.copy(evil, run / "model.zip")
    with pytest.raises(ValueError, match=r"old_run: not a trained policy \(missing policy.json, .*model.zip"):
        parse_controller(f"ppo:{run}", NOZZLE)
    assert not marker.exists()
    # the control: with the explicit opt-in SB3 does unpickle it, and the warning is printed
    with contextlib.suppress(Exception):
        load_trained(evil, "ppo", allow_pickle=True)
    assert marker.exists()
    assert "can execute arbitrary code" in capsys.readouterr().err


def test_a_pickle_in_place_of_the_weights_runs_nothing(tmp_path):
    marker = tmp_path / "pwned"
    run = _shipped_copy(tmp_path)
    evil = pickle.dumps(_Payload(marker))
    (run / "policy.safetensors").write_bytes(evil)
    with pytest.raises(ValueError, match=r"policy\.safetensors: its SHA-256 differs from the one in policy"):
        load_policy(run)
    _edit_json(run / "policy.json", lambda d: d.update(weights_sha256=hashlib.sha256(evil).hexdigest()))
    with pytest.raises(ValueError, match=r"policy\.safetensors: not a safetensors file"):
        parse_controller(f"ppo:{run}", NOZZLE)
    assert not marker.exists()


@pytest.mark.parametrize(
    ("file", "change", "message"),
    [
        ("policy.json", lambda d: d.update(code="__import__('os')"), "unexpected field\\(s\\) code"),
        ("policy.json", lambda d: d.pop("action_space"), "missing field\\(s\\) action_space"),
        ("policy.json", lambda d: d["policy_kwargs"].update(activation_fn="os.system"), "activation_fn"),
        ("policy.json", lambda d: d["policy_kwargs"].update(features_extractor_class=""), "unexpected"),
        ("policy.json", lambda d: d["policy_kwargs"].update(net_arch=[64, 32]), "weights do not fit|needs"),
        ("policy.json", lambda d: d["observation_space"].update(dtype="object"), "float32/float64 Box"),
        ("policy.json", lambda d: d["observation_space"].update(low=[0.0]), "low and high need 6 values"),
        ("policy.json", lambda d: d.update(algo="dqn"), "needs algo"),
        ("policy.json", lambda d: d.update(format="pickle"), "not an ssme-envs/policy v1 file"),
        ("normalization.json", lambda d: d.update(loader="pickle"), "unexpected field\\(s\\) loader"),
        ("normalization.json", lambda d: d.update(var=[1.0]), "one length"),
        ("normalization.json", lambda d: d.update(clip=-1), "positive"),
    ],
)
def test_tampered_json_is_a_clear_value_error(tmp_path, file, change, message):
    run = _shipped_copy(tmp_path)
    _edit_json(run / file, change)
    with pytest.raises(ValueError, match=message):
        load_policy(run)


def test_a_huge_net_arch_is_refused_before_anything_is_built(tmp_path):
    run = _shipped_copy(tmp_path)
    _edit_json(run / "policy.json", lambda d: d["policy_kwargs"].update(net_arch=[60000, 60000]))
    with pytest.raises(ValueError, match=r"net_arch \[60000, 60000\] does not fit the \d+ stored weights"):
        load_policy(run)


def test_an_old_run_converts_once_with_bit_equal_actions(tmp_path, capsys):
    run = tmp_path / "old"
    run.mkdir()
    venv = make_sb3_vec_env(NOZZLE, 2, seed=0)
    model = stable_baselines3.SAC("MlpPolicy", venv, device="cpu", seed=0, policy_kwargs={"net_arch": [8]})
    model.save(run / "model.zip")
    shutil.copy(shipped_policy(NOZZLE) / "normalization.json", run)
    (run / "config.toml").write_text(f'env = "{NOZZLE}"\nalgo = "sac"\n')
    assert convert_main([str(run)]) == 2  # the opt-in is required
    assert PICKLE_WARNING in capsys.readouterr().err and not (run / "policy.json").exists()
    assert convert_main([str(run), "--allow-pickle"]) == 0
    assert "actions bit-equal on 500 observations" in capsys.readouterr().out
    (run / "model.zip").unlink()
    obs = np.random.default_rng(2).standard_normal((200, 6))
    stats = read_normalization(run / "normalization.json")
    expected, _ = model.predict(stats.normalize(obs), deterministic=True)
    assert PolicyController(run, "sac").act(obs).tobytes() == np.clip(expected, -1, 1).tobytes()


def test_broken_directories_name_the_path_and_what_is_missing(tmp_path):
    with pytest.raises(ValueError, match="nowhere: no such policy directory"):
        parse_controller(f"ppo:{tmp_path / 'nowhere'}", NOZZLE)
    run = _shipped_copy(tmp_path)
    (run / "policy.safetensors").unlink()
    with pytest.raises(ValueError, match=f"{run}: not a trained policy \\(missing policy.safetensors\\)"):
        parse_controller(f"ppo:{run}", NOZZLE)
    (run / "policy.json").write_text("[1, 2]")
    (run / "policy.safetensors").write_bytes(b"")
    with pytest.raises(ValueError, match="expected a JSON object"):
        load_policy(run)
    (run / "policy.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_policy(run)
    # weights of another policy (other shapes), with a matching hash
    other = _shipped_copy(tmp_path, "EngineTracking-v0")
    good = _shipped_copy(tmp_path / "again")
    raw = (other / "policy.safetensors").read_bytes()
    (good / "policy.safetensors").write_bytes(raw)
    _edit_json(good / "policy.json", lambda d: d.update(weights_sha256=hashlib.sha256(raw).hexdigest()))
    with pytest.raises(ValueError, match=r"is torch.float32 .*the policy needs torch.float32"):
        load_policy(good)


def test_specs_check_the_algorithm_and_the_env(tmp_path):
    run = _shipped_copy(tmp_path)
    with pytest.raises(ValueError, match="holds a ppo policy, not sac"):
        parse_controller(f"sac:{run}", NOZZLE)
    with pytest.raises(ValueError, match=f"trained on {NOZZLE}, not {TRACKING}"):
        parse_controller(f"ppo:{run}", TRACKING)
    with pytest.raises(ValueError, match=r"choose from .* or ppo:RUN_DIR, sac:RUN_DIR, td3:RUN_DIR"):
        parse_controller("sac", NOZZLE)
    with pytest.raises(ValueError, match="a trained policy is a directory"):
        parse_controller(f"ppo:{run / 'policy.json'}", NOZZLE)


def _forbid_pickle(monkeypatch) -> list[str]:
    """Make every unpickling entry point record its name and raise; returns the record."""
    calls: list[str] = []

    def refuse(name):
        def fail(*args, **kwargs):
            calls.append(name)
            raise RuntimeError(f"{name} called")

        return fail

    class NoUnpickler(pickle.Unpickler):
        def __init__(self, *args, **kwargs):
            refuse("pickle.Unpickler")()

    monkeypatch.setattr(pickle, "loads", refuse("pickle.loads"))
    monkeypatch.setattr(pickle, "load", refuse("pickle.load"))
    monkeypatch.setattr(pickle, "Unpickler", NoUnpickler)
    monkeypatch.setattr(cloudpickle, "loads", refuse("cloudpickle.loads"))
    monkeypatch.setattr(torch, "load", refuse("torch.load"))
    return calls


def test_shipped_policies_load_and_act_without_any_pickle(monkeypatch):
    calls = _forbid_pickle(monkeypatch)
    rng = np.random.default_rng(0)
    for name in SHIPPED:
        directory = shipped_policy("ssme_envs/" + name.removesuffix("-identified"),
                                   "identified" if name.endswith("-identified") else "truth")  # fmt: skip
        assert sorted(p.name for p in directory.iterdir()) == [
            "config.toml", "normalization.json", "policy.json", "policy.safetensors", "training.json"
        ]  # fmt: skip
        controller = PolicyController(directory)
        obs = rng.standard_normal((32, controller.size))
        actions = controller.act(obs)
        assert actions.shape[0] == 32 and np.all(np.isfinite(actions)) and np.any(actions != 0)
    assert calls == []


def test_the_pickle_guard_above_does_catch_sb3_zips(tmp_path, monkeypatch):
    venv = make_sb3_vec_env(NOZZLE, 2, seed=0)
    model = stable_baselines3.PPO("MlpPolicy", venv, n_steps=8, batch_size=16, device="cpu",
                                  policy_kwargs={"net_arch": [8]})  # fmt: skip
    model.save(tmp_path / "sb3.zip")
    calls = _forbid_pickle(monkeypatch)
    with contextlib.suppress(Exception), pytest.warns(UserWarning):  # SB3 warns on what it cannot unpickle
        load_trained(tmp_path / "sb3.zip", "ppo", allow_pickle=True)
    assert "cloudpickle.loads" in calls


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_save_and_load_give_bit_equal_actions(algo, tmp_path):
    venv = make_sb3_vec_env(NOZZLE, 2, seed=0)
    extra = {"n_steps": 8, "batch_size": 16} if algo == "ppo" else {}
    model = getattr(stable_baselines3, algo.upper())(
        "MlpPolicy", venv, device="cpu", seed=3, policy_kwargs={"net_arch": [16, 8]}, **extra
    )
    save_policy(model.policy, algo, NOZZLE, tmp_path)
    (tmp_path / "normalization.json").write_text(
        json.dumps({"mean": [0.0] * 6, "var": [1.0] * 6, "count": 1.0, "clip": 10.0, "epsilon": 1e-8})
    )
    loaded = load_policy(tmp_path)
    assert type(loaded.policy) is type(model.policy) and loaded.algo == algo and loaded.env_id == NOZZLE
    obs = np.random.default_rng(1).standard_normal((300, 6)).astype(np.float32)
    before, _ = model.predict(obs, deterministic=True)
    after, _ = loaded.policy.predict(obs, deterministic=True)
    assert before.tobytes() == after.tobytes()
    tensors = safetensors.torch.load((tmp_path / "policy.safetensors").read_bytes())
    assert tensors.keys() == model.policy.state_dict().keys()


def test_to_vec_normalize_gives_sb3_the_shipped_statistics():
    path = shipped_policy(NOZZLE) / "normalization.json"
    stats = read_normalization(path)
    vec = to_vec_normalize(path, make_sb3_vec_env(NOZZLE, 3, seed=0))
    assert not vec.training and not vec.norm_reward and vec.clip_obs == stats.clip
    assert vec.obs_rms.count == stats.count > 1e6
    obs = vec.venv.reset()
    assert np.allclose(vec.normalize_obs(obs), stats.normalize(obs), rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="statistics of shape \\(6,\\) for observations of shape \\(10,\\)"):
        to_vec_normalize(path, make_sb3_vec_env(TRACKING, 1, seed=0))


def test_writes_are_atomic(tmp_path, monkeypatch):
    target = tmp_path / "policy.json"
    write_atomic(target, "old")

    def crash(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        write_atomic(target, "new")
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["policy.json"]


# --- bounded reads, special files, nesting, number ranges, damaged SB3 zips -----------------------

# float32's largest value, (2 - 2**-23) * 2**127, written out rather than taken from numpy
FLOAT32_MAX = 3.4028234663852886e38
POLICY_DIRS = sorted(
    p for root in ("agents/policies", "experiments/tried") for p in (REPO / root).iterdir() if p.is_dir()
)


@contextlib.contextmanager
def _no_hang(seconds: float = 10.0):
    """Fail instead of blocking for ever (a FIFO opened for reading waits for a writer)."""

    def fail(*args):
        raise TimeoutError(f"blocked for {seconds} s")

    previous = signal.signal(signal.SIGALRM, fail)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _make_special(path: Path, kind: str) -> None:
    path.unlink(missing_ok=True)
    if kind == "a directory":
        path.mkdir()
    elif kind == "a FIFO (named pipe)":
        os.mkfifo(path)
    else:  # a link to itself
        os.symlink(path.name, path)


@pytest.mark.parametrize("name", ["policy.json", "policy.safetensors", "normalization.json"])
@pytest.mark.parametrize("kind", ["a directory", "a FIFO (named pipe)", "a symbolic link loop"])
def test_a_special_file_in_a_policy_directory_is_named_as_such(tmp_path, name, kind):
    run = _shipped_copy(tmp_path)
    _make_special(run / name, kind)
    with _no_hang(), pytest.raises(ValueError) as info:
        load_policy(run)
    assert str(info.value) == f"{run}: not a trained policy ({name} is {kind}, not a regular file)"


@pytest.mark.parametrize(
    ("target", "kind"),
    [(os.devnull, "a character device"), ("fifo", "a FIFO (named pipe)"), ("dir", "a directory")],
)
def test_read_normalization_refuses_devices_fifos_and_directories_without_reading(tmp_path, target, kind):
    path = Path(target) if target == os.devnull else tmp_path / target
    if target == "fifo":
        os.mkfifo(path)
    elif target == "dir":
        path.mkdir()
    with (
        _no_hang(),
        pytest.raises(ValueError, match=f"^{path}: .*it is {re.escape(kind)}, not a regular file$"),
    ):
        read_normalization(path)


def test_weights_over_the_bound_are_refused_before_reading(tmp_path, monkeypatch):
    # the bound: a round 256 MiB, far above every policy shipped or tried (all are well under 1 MiB)
    assert policy_files.MAX_WEIGHTS_BYTES == 256 * 1024 * 1024
    assert all((d / "policy.safetensors").stat().st_size < 1024 * 1024 for d in POLICY_DIRS)
    run = _shipped_copy(tmp_path)
    with open(run / "policy.safetensors", "r+b") as fh:  # sparse: no disk, no memory
        fh.truncate(3 * 1024**3)
    with pytest.raises(ValueError, match=r"policy\.safetensors: larger than 256 MiB"):
        load_policy(run)
    # the boundary, on a small bound: exactly the limit is read (and here fails its hash), one more is not
    monkeypatch.setattr(policy_files, "MAX_WEIGHTS_BYTES", 1000)
    (run / "policy.safetensors").write_bytes(b"\0" * 1000)
    with pytest.raises(ValueError, match="SHA-256 differs"):
        load_policy(run)
    (run / "policy.safetensors").write_bytes(b"\0" * 1001)
    with pytest.raises(ValueError, match=r"policy\.safetensors: larger than 0 MiB"):
        load_policy(run)


@pytest.mark.parametrize("name", ["policy.json", "normalization.json"])
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[" * 200_000, "nested too deeply"),
        ('{"mean": [' + "7" * 5000 + "]}", "a number in it is too long to read"),
        ("\xff\xfe", "not valid JSON"),
    ],
    ids=["deep", "5000-digits", "not-utf8"],
)
def test_json_that_python_cannot_parse_is_a_value_error_naming_the_file(tmp_path, name, text, message):
    run = _shipped_copy(tmp_path)
    (run / name).write_bytes(text.encode("latin-1"))
    with pytest.raises(ValueError, match=f"^{re.escape(str(run / name))}: {message}"):
        load_policy(run)


def _normalization(tmp: Path, **change) -> Path:
    data = {"mean": [0.5, -2.0], "var": [4.0, 0.0], "count": 100.0, "clip": 10.0, "epsilon": 1e-8}
    data.update(change)
    path = tmp / "normalization.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("epsilon", math.inf), ("epsilon", 1e308), ("epsilon", 0.0), ("epsilon", -1e-8), ("epsilon", 1e-300),
        ("epsilon", 2.0), ("epsilon", True), ("epsilon", "1e-8"), ("epsilon", math.nan),
        ("clip", math.inf), ("clip", 1e-300), ("clip", 1e-4), ("clip", 1e308), ("clip", 4e38), ("clip", True),
        ("clip", None), ("count", math.inf), ("count", 0), ("count", True), ("count", 10**400),
        ("mean", [math.nan, 0.0]), ("var", [1.0, -1.0]), ("var", [1.0, "inf"]), ("mean", [True, 0.0]),
    ],
    ids=lambda v: repr(v)[:20],
)  # fmt: skip
def test_normalization_values_that_would_make_it_meaningless_are_refused(tmp_path, key, value):
    path = _normalization(tmp_path, **{key: value})
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: (mean and var|{key}) must be"):
        read_normalization(path)


def test_zero_variance_with_a_tiny_epsilon_and_a_huge_clip_cannot_reach_the_policy_as_nan(tmp_path):
    # the audit's case: 1 / sqrt(0 + 1e-300) = 1e150 times any offset, kept by a clip of 1e308, was
    # cast to float32 as inf (with a RuntimeWarning) and the network turned it into NaN
    path = _normalization(tmp_path, var=[0.0, 0.0], epsilon=1e-300, clip=1e308)
    with pytest.raises(ValueError, match=r"(epsilon|clip) must be"):
        read_normalization(path)


@settings(max_examples=150, deadline=None)
@given(
    key=st.sampled_from(["clip", "epsilon"]),
    value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-(10**400), 10**400)),
)
def test_clip_and_epsilon_are_accepted_exactly_in_their_ranges(key, value):
    # the ranges the loader documents: clip in [1e-3, float32 max], epsilon in [1e-12, 1]
    low, high = {"clip": (1e-3, FLOAT32_MAX), "epsilon": (1e-12, 1.0)}[key]
    accept = low <= value <= high  # False for NaN; exact for integers of any size
    with tempfile.TemporaryDirectory() as tmp:
        path = _normalization(Path(tmp), **{key: value})
        if accept:
            assert getattr(read_normalization(path), key) == float(value)
        else:
            with pytest.raises(ValueError, match=f"{key} must be a finite positive number"):
                read_normalization(path)


_finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(
    mean=_finite,
    var=st.floats(0.0, 1.7e308),
    clip=st.floats(1e-3, FLOAT32_MAX),
    epsilon=st.floats(1e-12, 1.0),
    obs=st.lists(st.floats(allow_nan=False), min_size=1, max_size=8),
)
def test_any_accepted_normalization_hands_the_policy_finite_clipped_float32(mean, var, clip, epsilon, obs):
    with tempfile.TemporaryDirectory() as tmp:
        stats = read_normalization(
            _normalization(Path(tmp), mean=[mean], var=[var], clip=clip, epsilon=epsilon)
        )
    x = np.array(obs).reshape(-1, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warning on the way
        out = stats.normalize(x)
    assert out.dtype == np.float32 and np.all(np.isfinite(out))
    assert np.all(np.abs(out) <= np.float32(clip))
    # the sign of each offset from the mean survives (0 where the scaled offset underflows)
    assert np.all(out * np.sign(x - mean) >= 0)


def test_every_shipped_and_tried_normalization_still_loads():
    assert len(POLICY_DIRS) >= 20
    for directory in POLICY_DIRS:
        stats = read_normalization(directory / "normalization.json")
        assert stats.clip == 10.0 and stats.epsilon == 1e-8  # SB3's VecNormalize settings in our configs


@pytest.mark.parametrize("version", [True, 1.0, "1", None])
def test_the_version_must_be_the_integer_one(tmp_path, version):
    run = _shipped_copy(tmp_path)
    _edit_json(run / "policy.json", lambda d: d.update(version=version))
    with pytest.raises(ValueError, match="not an ssme-envs/policy v1 file"):
        load_policy(run)


@pytest.mark.parametrize(
    ("field", "index", "value"),
    [("low", 0, -1e308), ("high", 5, 3.5e38), ("low", 2, -(10**39))],
    ids=["low-1e308", "high3.5e38", "low-int1e39"],
)
def test_space_bounds_beyond_float32_are_named_without_a_cast_warning(tmp_path, field, index, value):
    run = _shipped_copy(tmp_path)
    _edit_json(run / "policy.json", lambda d: d["observation_space"][field].__setitem__(index, value))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(
            ValueError, match=rf"observation_space\.{field}\[{index}\] = .* does not fit float32"
        ):
            load_policy(run)


def test_a_float64_space_keeps_bounds_float32_cannot_hold(tmp_path):
    run = _shipped_copy(tmp_path)
    _edit_json(run / "policy.json", lambda d: d["observation_space"].update(dtype="float64"))
    _edit_json(run / "policy.json", lambda d: d["observation_space"]["low"].__setitem__(0, -1e308))
    assert load_policy(run).policy.observation_space.low[0] == -1e308


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d["policy_kwargs"].update(log_std_init=10**400),
        lambda d: d.update(residual={"base": "pid", "scale": 10**400}),
        lambda d: d["observation_space"]["low"].__setitem__(0, -(10**400)),
    ],
)
def test_integers_beyond_float_range_are_value_errors(tmp_path, change):
    run = _shipped_copy(tmp_path)
    _edit_json(run / "policy.json", change)
    with pytest.raises(ValueError, match=re.escape(str(run / "policy.json"))):
        load_policy(run)


def _zip(path: Path, members: dict[str, str | bytes] | bytes) -> Path:
    if isinstance(members, bytes):
        path.write_bytes(members)
        return path
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


@pytest.mark.parametrize(
    ("members", "problem"),
    [
        ({"data": "{}"}, "cannot load it as an SB3 ppo zip (The observation_space and action_space"),
        ({}, "cannot load it as an SB3 ppo zip (No data found"),
        ({"data": "not json"}, "cannot load it as an SB3 ppo zip (its data entry is not valid JSON"),
        ({"data": "[1]"}, "cannot load it as an SB3 ppo zip ("),
        ({"data": "[" * 200_000}, "cannot load it as an SB3 ppo zip (its data entry is nested too deeply)"),
        ({"data": b"\xff\xfe"}, "cannot load it as an SB3 ppo zip (its data entry is not UTF-8 text)"),
        (b"not a zip", "not an SB3 zip: not a zip file"),
        (b"", "not an SB3 zip: not a zip file"),
    ],
    ids=[
        "data-empty-object",
        "no-members",
        "data-not-json",
        "data-list",
        "data-deep",
        "data-not-utf8",
        "not-a-zip",
        "empty-file",
    ],
)
def test_a_damaged_sb3_zip_is_one_error_line_naming_it(tmp_path, capsys, members, problem):
    bad = _zip(tmp_path / "bad.zip", members)
    args = ["evaluate", "--env", NOZZLE, "--controllers", f"ppo:{bad}", "--allow-pickle",
            "--scenario", "step", "--episodes", "1", "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(args) == 2
    lines = capsys.readouterr().err.splitlines()
    # the opt-in's warning, then the error: nothing else, no traceback
    assert len(lines) == 2 and "can execute arbitrary code" in lines[0], lines
    assert lines[1].startswith(f"error: {bad}: {problem}"), lines


def test_a_damaged_sb3_zip_prints_no_warning_or_traceback_from_a_real_process(tmp_path):
    bad = _zip(tmp_path / "bad.zip", {"data": "{}"})
    code = "import sys; from ssme_envs.cli import main; sys.exit(main(sys.argv[1:]))"
    args = ["evaluate", "--env", NOZZLE, "--controllers", f"ppo:{bad}", "--allow-pickle",
            "--scenario", "step", "--episodes", "1", "--out", str(tmp_path / "out")]  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    lines = proc.stderr.splitlines()
    assert len(lines) == 2 and lines[1].startswith(f"error: {bad}: cannot load it as an SB3 ppo zip"), lines


def test_the_converter_names_a_damaged_zip_in_one_line_and_writes_nothing(tmp_path, capsys):
    run = tmp_path / "old"
    run.mkdir()
    _zip(run / "model.zip", {"data": "not json"})
    (run / "config.toml").write_text(f'env = "{NOZZLE}"\nalgo = "ppo"\n')
    assert convert_main([str(run), "--allow-pickle"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and PICKLE_WARNING in lines[0], lines
    expected = f"error: {run / 'model.zip'}: cannot load it as an SB3 ppo zip (its data entry is not"
    assert lines[1].startswith(expected), lines
    assert sorted(p.name for p in run.iterdir()) == ["config.toml", "model.zip"]


@pytest.mark.parametrize("kind", ["a directory", "a FIFO (named pipe)", "a symbolic link loop"])
def test_an_sb3_zip_path_or_its_normalization_that_is_a_special_file_is_named(tmp_path, kind):
    zip_path = tmp_path / "model.zip"
    _make_special(zip_path, kind)
    with (
        _no_hang(),
        pytest.raises(ValueError, match=f"^{zip_path}: not an SB3 zip: it is {re.escape(kind)}, not"),
    ):
        load_trained(zip_path, "ppo", allow_pickle=True)
    zip_path = _zip(tmp_path / "other.zip", {"data": "{}"})
    _make_special(tmp_path / "normalization.json", kind)
    # refused, not skipped: the policy would otherwise see raw observations
    with _no_hang(), pytest.raises(ValueError, match=f"normalization.json: .*it is {re.escape(kind)}"):
        load_trained(zip_path, "ppo", allow_pickle=True)


@pytest.mark.parametrize("error", [OSError(5, "Input/output error"), MemoryError()])
def test_os_and_memory_errors_of_an_sb3_load_are_left_as_they_are(tmp_path, monkeypatch, capsys, error):
    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(stable_baselines3.PPO, "load", fail)
    with pytest.raises(type(error)) as info:
        load_trained(_zip(tmp_path / "m.zip", {"data": "{}"}), "ppo", allow_pickle=True)
    assert info.value is error
