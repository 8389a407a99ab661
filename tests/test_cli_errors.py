"""Audit catalogue of bad inputs and faults: every one ends with exit 2 (130 for Ctrl-C), one line
``error: ...`` on stderr, no traceback, within seconds, and the directory it ran in unchanged (an
earlier run in --out intact, nothing partial beside it). Then kills and Ctrl-C of real runs."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import ssme_envs.cli as cli
import ssme_envs.cli_commands as cli_commands
from ssme_envs.cli import main
from ssme_envs.identification import pipeline
from ssme_envs.identification.pipeline import default_experiment, write_record
from ssme_envs.models import identified_model
from ssme_envs.outputs import MARKER, directory_lock

HEADER = "t,beta_opov,beta_fpov,pc,mr\n"
ROWS = "".join(f"{0.04 * i:.2f},{i % 3 / 100},{i % 5 / 100},{i % 7 / 100},{i % 2 / 100}\n" for i in range(50))
SHORT = HEADER + ROWS  # parses, too short to identify


def _csv(rows: str) -> bytes:
    return (HEADER + rows).encode()


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """A good engine record (r.csv) and a good engine model (m.json), as bytes."""
    tmp = tmp_path_factory.mktemp("assets")
    record = default_experiment(100)["identification"]
    write_record(tmp / "r.csv", record)
    identified_model(100).save(tmp / "m.json")
    # each output moved, within the sample, by each valve at 30 % of the output's spread per valve spread
    feedthrough = 0.3 * record.y.std(axis=0)[:, None] / record.u.std(axis=0)[None, :]
    write_record(tmp / "ff.csv", replace(record, y=record.y + record.u @ feedthrough.T))
    names = ("r.csv", "m.json", "ff.csv")
    return {name: (tmp / name).read_bytes() for name in names}


def _model(assets, **changes) -> bytes:
    data = json.loads(assets["m.json"])
    data.update(changes)
    return json.dumps(data).encode()


def _model_text(assets, key: str, raw: str) -> bytes:
    """The model with ``key`` set to raw JSON text (numbers json.dumps cannot write)."""
    return _model(assets, **{key: "@@"}).replace(b'"@@"', raw.encode())


def _no_fsync_after_first(monkeypatch):
    """ENOSPC from the second fsync on: the run's marker is written, its model.json is not."""
    calls, real = [], os.fsync

    def fsync(fd):
        calls.append(fd)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


def _raise_in_identification(exc):
    def patch(monkeypatch):
        def identify(*args, **kwargs):
            raise exc

        monkeypatch.setattr(pipeline, "identify_record", identify)

    return patch


def _let_gymnasium_see_the_seed(monkeypatch):
    monkeypatch.setattr(cli_commands, "check_seed", lambda seed: None)  # the CLI's own check, bypassed


ENGINE = ["identify", "engine", "--data", "{d}/r.csv", "--out", "{d}/out"]
BAD_CSV = ["identify", "engine", "--data", "{d}/bad.csv", "--out", "{d}/out"]
VALIDATE = ["validate", "engine", "--model", "{d}/bad.json", "--data", "{d}/r.csv", "--out", "{d}/out"]
NOZZLE_EVAL = ["evaluate", "--env", "ssme_envs/NozzleTVC-v0", "--controllers", "zero", "--scenario", "step"]
EVAL = [*NOZZLE_EVAL, "--out", "{d}/out"]
TRAIN = ["train", "--out", "{d}/out", "--config"]
TUNE = [
    "tune",
    "--env",
    "ssme_envs/NozzleTVC-v0",
    "--algo",
    "ppo",
    "--storage",
    "journal:{d}/j.log",
    "--study",
    "s",
]
GOOD_CONFIG = b'env = "ssme_envs/NozzleTVC-v0"\nalgo = "ppo"\nsteps = 64\n'
DEEP = "[" * 100_000 + "]" * 100_000
PLANT_EVAL = ["evaluate", "--env", "ssme_envs/EngineTracking-v0", "--controllers", "pi", "--scenario",
              "pc_step", "--episodes", "1", "--plant", "{d}/bad.json", "--out", "{d}/out"]  # fmt: skip

# (id, input, argv, files under {d}: name -> bytes, "dir" or "asset:<name>", expected, patch, code)
CATALOGUE = [
    # CSV records
    ("csv-missing", "--data names no file", BAD_CSV, {}, "no such file", None, 2),
    ("csv-empty", "0-byte CSV", BAD_CSV, {"bad.csv": b""}, "needs a header row and data rows", None, 2),
    ("csv-header-only", "header, no rows", BAD_CSV, {"bad.csv": HEADER.encode()}, "needs a header row",
     None, 2),
    ("csv-blank", "blank lines only", BAD_CSV, {"bad.csv": b"\n\n\n"}, "needs a header row", None, 2),
    ("csv-ragged", "a row with 4 of 5 fields", BAD_CSV, {"bad.csv": _csv("0,1,2,3\n0.04,1,2,3,4\n")},
     "line 2 has 4 fields", None, 2),
    ("csv-text", "a cell 'x'", BAD_CSV, {"bad.csv": _csv("0,1,2,3,x\n0.04,1,2,3,4\n")},
     "column 'mr': 'x' is not a number", None, 2),
    ("csv-nan", "a NaN cell", BAD_CSV, {"bad.csv": _csv(ROWS.replace("0.01,", "nan,", 1))},
     "'beta_opov' has NaN", None, 2),
    ("csv-inf", "an inf cell", BAD_CSV, {"bad.csv": _csv(ROWS.replace("0.01,", "inf,", 1))},
     "NaN or inf", None, 2),
    ("csv-1e400", "a cell 1e400 (inf)", BAD_CSV, {"bad.csv": _csv(ROWS.replace("0.01,", "1e400,", 1))},
     "NaN or inf", None, 2),
    ("csv-1e300", "a cell 1e300", BAD_CSV, {"bad.csv": _csv(ROWS.replace("0.01,", "1e300,", 1))},
     "squares overflow float64", None, 2),
    ("csv-feedthrough", "outputs that move with the same sample's valves",
     ["identify", "engine", "--data", "{d}/ff.csv", "--out", "{d}/out"], {"ff.csv": "asset:ff.csv"},
     r"direct feedthrough: 'pc' on 'beta_opov'", None, 2),
    ("csv-columns", "no such columns", BAD_CSV, {"bad.csv": b"t,a,b,c,d\n0,1,2,3,4\n0.04,1,2,3,4\n"},
     "unknown column.*beta_opov", None, 2),
    ("csv-dup-header", "'pc' twice in the header", BAD_CSV,
     {"bad.csv": b"t,pc,beta_opov,beta_fpov,pc,mr\n0,1,2,3,4,5\n0.04,1,2,3,4,5\n"}, "'pc' appears twice",
     None, 2),
    ("csv-no-t", "no t column, no --dt", BAD_CSV,
     {"bad.csv": b"beta_opov,beta_fpov,pc,mr\n1,2,3,4\n1,2,3,4\n"},
     "no 't' column", None, 2),
    ("csv-irregular-t", "t steps 0.04 then 0.06", BAD_CSV,
     {"bad.csv": _csv("0,1,2,3,4\n0.04,1,2,3,4\n0.1,1,2,3,4\n")}, "not uniformly spaced", None, 2),
    ("csv-t-backwards", "t decreasing", BAD_CSV, {"bad.csv": _csv("0,1,2,3,4\n-0.04,1,2,3,4\n")},
     "must increase strictly", None, 2),
    ("csv-utf16-bom", "UTF-16 with its BOM", BAD_CSV, {"bad.csv": SHORT.encode("utf-16")}, "cannot read",
     None, 2),
    ("csv-utf8-bom-ragged", "UTF-8 BOM, then a ragged row", BAD_CSV,
     {"bad.csv": "\ufeff".encode() + _csv("0,1,2,3\n0.04,1,2,3,4\n")}, "line 2 has 4 fields", None, 2),
    ("csv-binary", "random bytes", BAD_CSV, {"bad.csv": np.random.default_rng(0).bytes(4000)},
     "cannot read|not a readable|header", None, 2),
    ("csv-huge-field", "a 200 kB field", BAD_CSV, {"bad.csv": _csv("0," + "9" * 200_000 + ",0,0,0\n")},
     "not a readable CSV record .*field larger than field limit", None, 2),
    ("csv-directory", "--data is a directory", BAD_CSV, {"bad.csv": "dir"}, "cannot read", None, 2),
    ("csv-zero-output", "output pc all zero", BAD_CSV,
     {"bad.csv": _csv("".join(f"{0.04 * i:.2f},{i % 3},{i % 5},0,{i % 2}\n" for i in range(200)))},
     "'pc' is zero throughout", None, 2),
    ("csv-too-short", "50 samples", BAD_CSV, {"bad.csv": SHORT.encode()}, "needs at least", None, 2),
    # model.json
    ("model-missing", "--model names no file", VALIDATE, {"r.csv": "asset:r.csv"}, "no such file", None, 2),
    ("model-empty", "0-byte model.json", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": b""},
     "not valid JSON", None, 2),
    ("model-not-json", "text", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": b"A = [[1]]"},
     "not valid JSON", None, 2),
    ("model-utf16", "UTF-16 JSON", VALIDATE, {"r.csv": "asset:r.csv",
     "bad.json": '{"A": 1}'.encode("utf-16")},
     "not valid JSON", None, 2),
    ("model-directory", "--model is a directory", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": "dir"},
     "not valid JSON", None, 2),
    ("model-device", "--model /dev/null", [*VALIDATE[:3], os.devnull, *VALIDATE[4:]],
     {"r.csv": "asset:r.csv"}, f"{os.devnull}: not valid JSON: it is a character device, not a regular file",
     None, 2),
    ("model-list", "a JSON list", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": b"[]"},
     "expected a JSON object, got list", None, 2),
    ("model-no-A", "A missing", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": "drop:A"},
     r"missing key\(s\) A", None, 2),
    ("model-A-text", "A a string", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": "set:A:\"x\""},
     "A must be a numeric matrix", None, 2),
    ("model-A-object", "A an object", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": 'set:A:{"a": 1}'},
     "A must be a numeric matrix", None, 2),
    ("model-A-nan", "A holds NaN", VALIDATE,
     {"r.csv": "asset:r.csv", "bad.json": "set:A:[[NaN, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"},
     "A contains NaN or inf", None, 2),
    ("model-A-1e400", "A holds 1e400", VALIDATE,
     {"r.csv": "asset:r.csv",
     "bad.json": "set:A:[[1e400, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"},
     "A contains NaN or inf", None, 2),
    ("model-dt-bigint", "dt = 10**400", VALIDATE, {"r.csv": "asset:r.csv",
     "bad.json": "set:dt:1" + "0" * 400},
     "bad.json: not an engine model", None, 2),
    ("model-dt-bigint-named", "dt = 10**400", VALIDATE, {"r.csv": "asset:r.csv",
     "bad.json": "set:dt:1" + "0" * 400},
     "bad.json: not an engine model: dt must be a positive number of seconds, got an integer of about "
     "401 digits",
     None, 2),
    ("model-5001-digits", "dt = 10**5000", VALIDATE, {"r.csv": "asset:r.csv",
     "bad.json": "set:dt:1" + "0" * 5000},
     r"bad.json: a number in it is too long to read \(Exceeds the limit \(4300 digits\)", None, 2),
    ("model-states", "A with 513 rows", VALIDATE,
     {"r.csv": "asset:r.csv", "bad.json": "set:A:[" + "[0], " * 512 + "[0]]"},
     r"bad.json: A has 513 rows \(states\); a model file holds at most 512", None, 2),
    ("plant-lambda-object", "evaluate --plant with lambda an object", PLANT_EVAL,
     {"bad.json": 'set:lambda:{"a": 1}'},
     "bad.json: not an engine model: lambda must be a list of 2 finite gains", None, 2),
    ("model-dt-text", "dt a string", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": 'set:dt:"fast"'},
     "dt must be a positive number", None, 2),
    ("model-B-shape", "B 3 rows", VALIDATE,
     {"r.csv": "asset:r.csv", "bad.json": "set:B:[[0, 0], [0, 0], [0, 0]]"}, r"B has shape \(3, 2\)", None,
     2),
    ("model-schema", "another schema", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": 'set:schema:"other"'},
     "schema is 'other'", None, 2),
    ("model-deep-lists", "100k nested lists", VALIDATE, {"r.csv": "asset:r.csv", "bad.json": DEEP.encode()},
     "nested too deeply", None, 2),
    ("model-deep-objects", "100k nested objects", VALIDATE,
     {"r.csv": "asset:r.csv", "bad.json": ('{"a":' * 100_000 + "1" + "}" * 100_000).encode()},
     "nested too deeply", None, 2),
    # options
    ("episodes-zero", "--episodes 0", [*EVAL, "--episodes", "0"], {}, "--episodes must be a positive integer",
     None, 2),
    ("episodes-negative", "--episodes -3", [*EVAL, "--episodes", "-3"], {}, "--episodes must be", None, 2),
    ("episodes-huge", "--episodes 10**12", [*EVAL, "--episodes", "1000000000000"], {},
     r"--episodes 1000000000000 needs about .* of memory.*available.*use at most \d+", None, 2),
    ("episodes-text", "--episodes x", [*EVAL, "--episodes", "x"], {}, "invalid int value", None, 2),
    ("report-episodes-huge", "report --episodes 10**9", ["report", "--episodes", "1000000000", "--out",
     "{d}/out"],
     {}, "--episodes 1000000000 needs about", None, 2),
    ("report-episodes-zero", "report --episodes 0", ["report", "--episodes", "0", "--out", "{d}/out"], {},
     "--episodes must be", None, 2),
    ("seed-negative", "evaluate --seed -1", [*EVAL, "--seed", "-1"], {}, "--seed must be a non-negative",
     None, 2),
    ("engine-seed-negative", "identify --seed -1", ["identify", "engine", "--seed", "-1", "--out",
     "{d}/out"], {},
     "--seed must be a non-negative", None, 2),
    ("nozzle-seed-negative", "identify nozzle --seed -1", ["identify", "nozzle", "--seed", "-1", "--out",
     "{d}/o"],
     {}, "--seed must be a non-negative", None, 2),
    ("gymnasium-seed", "--seed -1 reaching gymnasium", [*EVAL, "--episodes", "1", "--seed", "-1"], {},
     "gymnasium: Seed must be greater or equal to zero", _let_gymnasium_see_the_seed, 2),
    ("unknown-env", "--env Foo-v0", ["evaluate", "--env", "Foo-v0", "--out", "{d}/out"], {},
     "unknown env 'Foo-v0'; choose one of ssme_envs/EngineTracking-v0", None, 2),
    ("unknown-controller", "--controllers pi", [*EVAL[:4], "pi", *EVAL[5:]], {},
     "unknown controller 'pi' for ssme_envs/NozzleTVC-v0; choose from", None, 2),
    ("controller-empty-design", "--controllers zero:", [*EVAL[:4], "zero:", *EVAL[5:]], {},
     "controller spec 'zero:' names nothing after ':'", None, 2),
    ("empty-controller", "--controllers ,", [*EVAL[:4], ",", *EVAL[5:]], {}, "comma-separated list of names",
     None, 2),
    ("controller-twice", "--controllers zero,zero", [*EVAL[:4], "zero,zero", *EVAL[5:]], {},
     "controller zero is listed twice", None, 2),
    ("zero-design", "--controllers zero:truth", [*EVAL[:4], "zero:truth", *EVAL[5:]], {},
     "'zero:truth': the zero controller is designed on no model; write 'zero'", None, 2),
    ("scenario-twice", "--scenario step,step", [*EVAL[:6], "step,step", *EVAL[7:]], {},
     "scenario step is listed twice", None, 2),
    ("bench-size-twice", "bench --sizes 1,1", ["bench", "--sizes", "1,1"], {}, "size 1 is listed twice",
     None, 2),
    ("bench-env-twice", "bench --env E --env E",
     ["bench", "--sizes", "1", "--env", "ssme_envs/NozzleTVC-v0", "--env", "ssme_envs/NozzleTVC-v0"], {},
     "env ssme_envs/NozzleTVC-v0 is listed twice", None, 2),
    ("bench-actions-twice", "bench --actions zero,zero",
     ["bench", "--sizes", "1", "--actions", "zero,zero"], {}, "action kind zero is listed twice", None, 2),
    ("unknown-scenario", "--scenario moon", [*EVAL[:6], "moon", *EVAL[7:]], {}, "unknown scenario moon",
     None, 2),
    ("dt-nan", "--dt nan", [*ENGINE, "--dt", "nan"], {"r.csv": "asset:r.csv"}, "--dt must be a positive",
     None, 2),
    ("dt-negative", "--dt -0.04", [*ENGINE, "--dt", "-0.04"], {"r.csv": "asset:r.csv"},
     "--dt must be a positive",
     None, 2),
    ("dt-over-a-day", "--dt 1e300", [*ENGINE, "--dt", "1e300"], {"r.csv": "asset:r.csv"},
     r"--dt must be at most 86400 s \(a day\)", None, 2),
    ("nozzle-dt-over-a-day", "identify nozzle --dt 1e300", ["identify", "nozzle", "--data", "{d}/r.csv",
     "--dt", "1e300", "--out", "{d}/out"], {"r.csv": "asset:r.csv"}, "--dt must be at most 86400 s", None, 2),
    ("validate-dt-over-a-day", "validate engine --dt 1e300", [*VALIDATE[:3], "{d}/m.json", *VALIDATE[4:],
     "--dt", "1e300"], {"r.csv": "asset:r.csv", "m.json": "asset:m.json"}, "--dt must be at most 86400 s",
     None, 2),
    ("rank-tol-nan", "--rank-tol nan", [*ENGINE, "--rank-tol", "nan"], {"r.csv": "asset:r.csv"},
     "--rank-tol must be a finite", None, 2),
    ("dt-underscore", "--dt 0_04", [*ENGINE, "--dt", "0_04"], {"r.csv": "asset:r.csv"},
     "argument --dt: invalid float value: '0_04'", None, 2),
    ("episodes-underscore", "--episodes 1_0", [*EVAL, "--episodes", "1_0"], {},
     "argument --episodes: invalid int value: '1_0'", None, 2),
    ("indices-empty", "--indices ''", [*ENGINE, "--indices", ""], {"r.csv": "asset:r.csv"},
     "--indices must be comma-separated positive integers, got ''", None, 2),
    ("indices-underscore", "--indices 1_0,2", [*ENGINE, "--indices", "1_0,2"], {"r.csv": "asset:r.csv"},
     "--indices must be comma-separated positive integers, got '1_0,2'", None, 2),
    ("indices-zero", "--indices 0,2", [*ENGINE, "--indices", "0,2"], {"r.csv": "asset:r.csv"},
     "--indices must be positive", None, 2),
    ("max-index-zero", "--max-index 0", [*ENGINE, "--max-index", "0"], {"r.csv": "asset:r.csv"},
     "max_index must be >= 1", None, 2),
    ("max-index-huge", "--max-index 10**9", [*ENGINE, "--max-index", "1000000000"], {"r.csv": "asset:r.csv"},
     "needs at least", None, 2),
    ("seed-with-data", "--seed with --data", [*ENGINE, "--seed", "1"], {"r.csv": "asset:r.csv"},
     "--seed applies to the embedded experiment only", None, 2),
    ("workers-zero", "--workers 0", ["identify", "nozzle", "--workers", "0", "--out", "{d}/out"], {},
     "--workers must be a positive integer", None, 2),
    ("workers-huge", "--workers 10**9", ["identify", "nozzle", "--workers", "1000000000", "--out",
     "{d}/out"], {},
     "--workers 1000000000 needs about", None, 2),
    ("normalization-inf", "--normalization-a inf", ["identify", "nozzle", "--normalization-a", "inf", "--out",
     "{d}/out"], {}, "--normalization-a must be a positive", None, 2),
    ("dt-under-a-nanosecond", "--dt 1e-300", [*ENGINE, "--dt", "1e-300"], {"r.csv": "asset:r.csv"},
     r"--dt must be at least 1e-09 s \(a nanosecond\), got 1e-300", None, 2),
    ("train-config-dir", "train --config DIR", [*TRAIN, "{d}/c.toml"], {"c.toml": "dir"},
     r"cannot read config .*c\.toml: not a regular file \(a directory\)", None, 2),
    ("train-config-not-utf8", "train --config latin-1", [*TRAIN, "{d}/c.toml"], {"c.toml": b"env = '\xe9'\n"},
     r"cannot read config .*c\.toml: not UTF-8 text", None, 2),
    ("train-seed-huge", "train --seed 10**14", [*TRAIN, "{d}/c.toml", "--seed", "99999999999999"],
     {"c.toml": GOOD_CONFIG}, r"--seed must be within 0-4294967295, got 99999999999999", None, 2),
    ("train-config-seed-huge", "seed = 10**14 in the config", [*TRAIN, "{d}/c.toml"],
     {"c.toml": GOOD_CONFIG + b"seed = 99999999999999\n"},
     r"config .*c\.toml: seed must be within 0-4294967295, got 99999999999999", None, 2),
    ("tune-seed-huge", "tune --seed 10**14", [*TUNE, "--seed", "99999999999999"], {},
     r"--seed must be an integer within 0-4294967295", None, 2),
    ("tune-eval-episodes-huge", "tune --eval-episodes 10**12", [*TUNE, "--eval-episodes", "999999999999"], {},
     r"--eval-episodes 999999999999 needs about", None, 2),
    ("sizes-zero", "bench --sizes 0", ["bench", "--sizes", "0"], {}, "--sizes must be positive", None, 2),
    ("sizes-huge", "bench --sizes 10**12", ["bench", "--sizes", "1000000000000"], {},
     "--sizes 1000000000000 needs about", None, 2),
    ("sizes-text", "bench --sizes x", ["bench", "--sizes", "x"], {}, "--sizes must be comma-separated",
     None, 2),
    ("rounds-huge", "bench --rounds 1000", ["bench", "--rounds", "1000"], {}, "--rounds must be within 1-100",
     None, 2),
    ("bench-env", "bench --env Foo", ["bench", "--env", "Foo"], {}, "unknown env Foo", None, 2),
    ("bench-out-dir", "bench --out DIR", ["bench", "--sizes", "1", "--out", "{d}/out"], {},
     "must be a file in an existing directory", None, 2),
    ("unknown-command", "ssme-envs frobnicate", ["frobnicate"], {}, "invalid choice", None, 2),
    ("no-out", "identify engine without --out", ["identify", "engine"], {}, "--out", None, 2),
    # output paths
    ("out-is-file", "--out names a file", [*EVAL[:-1], "{d}/file"], {"file": b"keep"},
     "exists and is not a directory", None, 2),
    ("out-under-file", "--out file/sub", [*EVAL[:-1], "{d}/file/sub"], {"file": b"keep"},
     "is a file, not a dir",
     None, 2),
    ("out-foreign", "--out holds other files", [*EVAL[:-1], "{d}/mine"], {"mine/thesis.tex": b"precious"},
     "not empty and was not written by ssme-envs", None, 2),
    ("out-holds-data", "--data inside the earlier run in --out",
     ["identify", "engine", "--data", "{d}/out/r.csv", "--out", "{d}/out"],
     {"out/r.csv": "asset:r.csv", "out/.ssme-envs-run": b"{}"}, r"--data .*/out/r.csv lies in --out",
     None, 2),
    ("out-holds-plant", "evaluate --plant inside --out",
     [*PLANT_EVAL[:-3], "{d}/out/m.json", "--out", "{d}/out"],
     {"out/m.json": b"{}", "out/.ssme-envs-run": b"{}"}, r"--plant .*/out/m.json lies in --out", None, 2),
    ("bench-out-dir-name", "bench --out NEW/",
     ["bench", "--env", "ssme_envs/NozzleTVC-v0", "--out", "{d}/new/"], {},
     r"--out .*/new/: must be a file, and this names a directory", None, 2),
    ("out-root", "--out /", [*EVAL[:-1], "/"], {}, "needs a name", None, 2),
    ("out-locked", "another run holds --out", ENGINE, {"r.csv": "asset:r.csv"},
     rf"out is in use by another ssme-envs run \(pid {os.getpid()}, lock file", "lock", 2),
    # faults
    ("disk-full", "ENOSPC writing model.json", ENGINE, {"r.csv": "asset:r.csv"},
     r"out/model.json: No space left on device", _no_fsync_after_first, 2),
    ("out-of-memory", "MemoryError in the fit", ENGINE, {"r.csv": "asset:r.csv"}, "out of memory",
     _raise_in_identification(MemoryError()), 2),
    ("ctrl-c", "KeyboardInterrupt in the fit", ENGINE, {"r.csv": "asset:r.csv"}, r"interrupted \(Ctrl-C\)",
     _raise_in_identification(KeyboardInterrupt()), 130),
]  # fmt: skip


def _files(root: Path, spec: dict, assets) -> None:
    (root / "out").mkdir()  # an earlier run that no failure may touch
    (root / "out" / MARKER).write_text("{}")
    (root / "out" / "model.json").write_text("the earlier model\n")
    for name, value in spec.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if value == "dir":
            path.mkdir()
        elif isinstance(value, str) and value.startswith("asset:"):
            path.write_bytes(assets[value[6:]])
        elif isinstance(value, str) and value.startswith("drop:"):
            data = json.loads(assets["m.json"])
            del data[value[5:]]
            path.write_text(json.dumps(data))
        elif isinstance(value, str) and value.startswith("set:"):
            _, key, raw = value.split(":", 2)
            path.write_bytes(_model_text(assets, key, raw))
        else:
            path.write_bytes(value)


def _tree(root: Path) -> dict[str, bytes | None]:
    out: dict[str, bytes | None] = {}
    for path in sorted(root.rglob("*")):
        out[str(path.relative_to(root))] = None if path.is_dir() else path.read_bytes()
    return out


@pytest.mark.parametrize(
    ("what", "argv", "files", "expected", "patch", "code"),
    [pytest.param(*row[1:], id=row[0]) for row in CATALOGUE],
)
def test_catalogue(tmp_path, capsys, monkeypatch, assets, what, argv, files, expected, patch, code):
    _files(tmp_path, files, assets)
    before = _tree(tmp_path)
    argv = [a.format(d=tmp_path) for a in argv]
    if callable(patch):
        patch(monkeypatch)
    start = time.perf_counter()
    if patch == "lock":
        with directory_lock(tmp_path / "out"):  # held by this process: its pid is named
            got = main(argv)
    else:
        got = main(argv)
    seconds = time.perf_counter() - start
    captured = capsys.readouterr()
    err = captured.err
    assert got == code, err
    assert re.fullmatch(r"error: [^\n]+\n", err), err  # one line
    assert "Traceback" not in err
    assert re.search(expected, err), err
    assert _tree(tmp_path) == before  # the earlier run intact, nothing partial, no temporaries
    assert seconds < 20, f"{what}: {seconds:.1f} s"  # refused up front, not after a long run


def test_catalogue_unwritable_parent(tmp_path, capsys):
    if os.geteuid() != 0:
        parent = tmp_path / "read-only"
        parent.mkdir(mode=0o500)
    elif Path("/sys").is_dir():  # root writes anywhere but in sysfs
        parent = Path("/sys")
    else:  # pragma: no cover
        pytest.skip("no directory this user cannot write")
    code = main([*[a for a in NOZZLE_EVAL], "--out", str(parent / "out")])
    err = capsys.readouterr().err
    assert code == 2 and re.fullmatch(r"error: [^\n]+\n", err), err
    assert re.search("Permission denied|Operation not permitted|Read-only", err), err
    assert not (parent / "out").exists()


def test_a_fifo_named_as_the_model_is_refused_without_waiting_for_a_writer(tmp_path, capsys, assets):
    (tmp_path / "r.csv").write_bytes(assets["r.csv"])
    fifo = tmp_path / "x.json"
    os.mkfifo(fifo)

    def unblock() -> None:  # a loader blocked opening the FIFO then reads end of file: a failure, not a hang
        time.sleep(5.0)
        with contextlib.suppress(OSError):  # no reader waiting: nothing to unblock
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))

    threading.Thread(target=unblock, daemon=True).start()
    argv = [a.format(d=tmp_path) for a in VALIDATE]
    argv[3] = str(fifo)
    start = time.perf_counter()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"error: {fifo}: not valid JSON: it is a FIFO (named pipe), not a regular file\n", err
    assert time.perf_counter() - start < 5.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([*TRAIN, "{d}/fifo"], "error: cannot read config {d}/fifo: not a regular file (a FIFO)\n"),
        (
            ["tune", "--env", "ssme_envs/NozzleTVC-v0", "--algo", "ppo", "--storage", "journal:{d}/fifo",
             "--study", "s"],
            "error: --storage journal:{d}/fifo: {d}/fifo is not a regular file\n",
        ),
    ],
    ids=["train-config", "tune-journal"],
)  # fmt: skip
def test_a_fifo_named_as_a_config_or_journal_is_refused_without_waiting(tmp_path, capsys, argv, message):
    os.mkfifo(tmp_path / "fifo")
    fifo = tmp_path / "fifo"

    def unblock() -> None:  # a reader blocked opening the FIFO then reads end of file, not a hang
        time.sleep(5.0)
        with contextlib.suppress(OSError):
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))

    threading.Thread(target=unblock, daemon=True).start()
    start = time.perf_counter()
    assert main([a.format(d=tmp_path) for a in argv]) == 2
    assert capsys.readouterr().err == message.format(d=tmp_path)
    assert time.perf_counter() - start < 5.0


def test_no_command_prints_the_usage_and_exits_2(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: ssme-envs") and "identify" in err and "evaluate" in err
    assert err.splitlines()[-1].startswith("error: ssme-envs: choose one of identify")


def test_every_subcommand_has_a_description(capsys):
    parser = cli.build_parser()
    commands = parser._subparsers._group_actions[0].choices
    for name, sub in commands.items():
        assert sub.description, name
    with pytest.raises(SystemExit) as stop:
        main(["evaluate", "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    from agents import controller_names
    from ssme_envs.evaluation import SCENARIOS

    for env_id, scenarios in SCENARIOS.items():  # every env, scenario and controller, none re-typed
        assert env_id in text
        block = text.split(env_id, 1)[1]
        assert all(s in block for s in scenarios)
        assert all(c in block for c in controller_names(env_id))


# --- kills and Ctrl-C of real runs (subprocesses) -------------------------------------------------

KILLER = textwrap.dedent(
    """
    import builtins, os, signal, sys
    import ssme_envs.outputs as outputs
    from ssme_envs.cli import main

    point, target = sys.argv[1], os.path.abspath(sys.argv[2])
    opened, real_open, real_replace, real_rename = {}, os.open, os.replace, os.rename

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    def os_open(path, flags, mode=0o777, *args, **kwargs):
        fd = real_open(path, flags, mode, *args, **kwargs)
        opened[fd] = os.fspath(path)
        return fd

    def file_open(fd, mode, **kwargs):  # outputs' temporary files: cut model.json's write in half
        fh = builtins.open(fd, mode, **kwargs)
        if point == "write" and ".model.json." in opened.get(fd, ""):
            write = fh.write
            def half(text):
                write(text[: len(text) // 2])
                fh.flush()
                die()
            fh.write = half
        return fh

    def replace(src, dst, *args, **kwargs):
        if point == "rename" and os.fspath(dst).endswith("model.json"):
            die()
        return real_replace(src, dst, *args, **kwargs)

    def rename(src, dst, *args, **kwargs):
        real_rename(src, dst, *args, **kwargs)
        if point == "swap" and os.fspath(src) == target:
            die()  # between the two renames of the swap: --out is aside

    os.open, os.replace, os.rename, outputs.open = os_open, replace, rename, file_open
    sys.exit(main(sys.argv[3:]))
    """
)


@pytest.fixture(scope="module")
def earlier_run(tmp_path_factory, assets):
    """A real `identify engine --data r.csv` run: the directory a killed rerun must not damage."""
    root = tmp_path_factory.mktemp("earlier")
    (root / "r.csv").write_bytes(assets["r.csv"])
    assert main(["identify", "engine", "--data", str(root / "r.csv"), "--out", str(root / "out")]) == 0
    return root


def _rerun(tmp_path, earlier_run, point):
    shutil.copytree(earlier_run, tmp_path, dirs_exist_ok=True)
    (tmp_path / "kill.py").write_text(KILLER)
    before = _tree(tmp_path / "out")
    argv = ["identify", "engine", "--data", str(tmp_path / "r.csv"), "--out", str(tmp_path / "out")]
    proc = subprocess.run(
        [sys.executable, str(tmp_path / "kill.py"), point, str(tmp_path / "out"), *argv],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    return before, argv


@pytest.mark.parametrize("point", ["write", "rename"])
def test_killed_while_writing_the_model_the_earlier_model_is_intact(tmp_path, capsys, earlier_run, point):
    before, argv = _rerun(tmp_path, earlier_run, point)
    assert _tree(tmp_path / "out") == before  # model.json byte-equal, no temporary file in --out
    (building,) = tmp_path.glob(".out.new-*")  # the killed run's own directory, beside --out
    (partial,) = building.glob(".model.json.*.tmp")
    if point == "write":
        assert 0 < partial.stat().st_size < len(before["model.json"]) * 0.6  # half a model
    assert main(argv) == 0  # the next run cleans up and replaces the earlier one whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kill.py", "out", "r.csv"]
    again, earlier = (
        json.loads(m) for m in ((tmp_path / "out" / "model.json").read_bytes(), before["model.json"])
    )
    assert again["fit"].pop("data") != earlier["fit"].pop("data")  # the record's path: this directory's
    assert again == earlier  # same data, same model
    assert "replaced the earlier run" in capsys.readouterr().err


def test_killed_between_the_renames_of_the_swap_the_next_run_puts_it_back(tmp_path, earlier_run):
    before, _ = _rerun(tmp_path, earlier_run, "swap")
    assert not (tmp_path / "out").exists()
    (aside,) = tmp_path.glob(".out.old-*")
    assert _tree(aside) == before
    from ssme_envs.outputs import run_directory

    with pytest.raises(RuntimeError), run_directory(tmp_path / "out"):
        raise RuntimeError("the next run fails too")
    assert _tree(tmp_path / "out") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kill.py", "out", "r.csv"]


def test_ctrl_c_exits_130_with_one_line_and_leaves_the_earlier_run(tmp_path, earlier_run):
    shutil.copytree(earlier_run, tmp_path, dirs_exist_ok=True)
    before = _tree(tmp_path / "out")
    proc = subprocess.Popen(
        [sys.executable, "-m", "ssme_envs.cli", "identify", "engine", "--data", str(tmp_path / "r.csv"),
         "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".out.new-*")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    time.sleep(0.3)  # inside the identification
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err == "error: interrupted (Ctrl-C)\n"
    assert _tree(tmp_path / "out") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "r.csv"]


INTERRUPTED_IN_EXEC = """
import runpy, sys
from contextlib import contextmanager
import ssme_envs.cli_checks as checks

@contextmanager
def interrupted():
    exec("raise KeyboardInterrupt")  # lands inside an exec of a string, as in making a dataclass
    yield

checks.sigint_in_main_process = interrupted
sys.argv = ["ssme-envs", "identify", "engine", "--out", sys.argv[1]]
runpy.run_module("ssme_envs.cli", run_name="__main__", alter_sys=True)
"""


def test_ctrl_c_through_an_exec_of_a_string_still_exits_130_under_python_m(tmp_path):
    """CPython's ``python -m`` ends a process by SIGINT (return code -2) once a KeyboardInterrupt has
    passed through an exec of a string, even a caught one; the CLI exits 130 all the same."""
    (tmp_path / "interrupted_in_exec.py").write_text(INTERRUPTED_IN_EXEC)
    proc = subprocess.run(
        [sys.executable, "-m", "interrupted_in_exec", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=120, check=False, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr == "error: interrupted (Ctrl-C)\n"


@pytest.mark.parametrize(
    ("config", "algo", "option"),
    [
        ("num_envs = 1000000000\n", "ppo", "num_envs"),
        ("[hyperparameters]\nbuffer_size = 100000000000\n", "sac", "buffer_size"),
    ],
)
def test_train_counts_beyond_memory_are_refused_before_work(tmp_path, capsys, config, algo, option):
    path = tmp_path / "big.toml"
    path.write_text(config)
    out = tmp_path / "run"
    argv = ["train", "--env", "ssme_envs/NozzleTVC-v0", "--algo", algo, "--steps", "100"]
    assert main([*argv, "--config", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {option} ") and "of memory" in err and err.count("\n") == 1
    assert not out.exists()


def test_ctrl_c_inside_an_import_exits_130_not_a_traceback(monkeypatch, capsys):
    """A C extension's module init turns a Ctrl-C into ImportError("initialization failed") with the
    KeyboardInterrupt as its cause (seen importing matplotlib under load): still an interrupt."""
    import ssme_envs.cli as cli

    def interrupted_import(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr(cli, "_dispatch", interrupted_import)
    assert cli.main(["report", "--out", "x"]) == 130
    assert capsys.readouterr().err == "error: interrupted (Ctrl-C)\n"


@pytest.mark.parametrize(("plant", "module"), [("engine", "pipeline"), ("nozzle", "nozzle_bench")])
def test_identify_help_states_the_default_seed(plant, module, capsys):
    """The help's default seed (written out: reading it would import the identification at
    every start of the CLI) is the embedded experiment's."""
    import importlib

    with pytest.raises(SystemExit):
        main(["identify", plant, "--help"])
    seed = importlib.import_module(f"ssme_envs.identification.{module}").DEFAULT_SEED
    assert f"(default: {seed})" in " ".join(capsys.readouterr().out.split())
