"""Policies as data: safetensors + JSON, no pickle; crafted files run nothing and fail clearly."""

import base64
import contextlib
import hashlib
import json
import os
import pickle
import shutil
import zipfile
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import safetensors.torch
import stable_baselines3
import torch

from agents import parse_controller
from agents.policy_files import (
    PICKLE_WARNING,
    load_policy,
    read_normalization,
    save_policy,
    to_vec_normalize,
    write_atomic,
)
from agents.policy_zip import _main as convert_main
from agents.sb3 import SHIPPED, PolicyController, load_trained, shipped_policy
from ssme_envs.cli import main
from ssme_envs.envs.sb3_adapter import make_sb3_vec_env

NOZZLE = "ssme_envs/NozzleTVC-v0"
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
