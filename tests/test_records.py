"""CSV records: duplicated header names, a UTF-8 BOM, degenerate validation records,
`ssme-envs validate engine` keeping records that share a file name apart, epoch-style time
stamps, columns left unread, sample times over a day, special and oversized files."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ssme_envs.cli import main
from ssme_envs.identification.records import (
    MAX_CSV_BYTES,
    check_validation_record,
    read_columns,
    read_text,
    record_labels,
)
from ssme_envs.models import identified_model

DT = 0.04  # the packaged engine models' sample time
HEADER = ("t", "beta_opov", "beta_fpov", "pc", "mr")
SAMPLES = 60


def _good(seed: int = 0) -> np.ndarray:
    """A record the 110 % model can be scored on: PRBS-like valves, noisy outputs (no t column)."""
    rng = np.random.default_rng(seed)
    u = rng.choice([-0.01, 0.01], size=(SAMPLES, 2))
    y = 0.01 * rng.standard_normal((SAMPLES, 2))
    return np.column_stack([u, y])


def _csv(path, data: np.ndarray, header=HEADER, bom: bool = False):
    t = np.arange(data.shape[0]) * DT
    rows = [",".join(header)] + [",".join(repr(float(v)) for v in row) for row in np.column_stack([t, data])]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(("\ufeff" if bom else "") + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def _one_error_line(code: int, err: str, pattern: str) -> None:
    """The CLI's convention (as in test_pipeline_cli): exit 2, one line `error: ...`, no traceback."""
    assert code == 2, err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    assert re.search(pattern, err), err


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "model.json"
    identified_model(110).save(path)
    return path


# --- header ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("header", "name", "times"),
    [
        ("t,beta_opov,beta_fpov,pc,mr,pc", "pc", "twice"),
        ("t,t,beta_opov,beta_fpov,pc,mr", "t", "twice"),
        ("t,beta_opov,beta_fpov,pc,mr,other, other", "other", "twice"),  # after stripping blanks
        ("t,x,beta_opov,x,beta_fpov,pc,mr,x", "x", "3 times"),  # a column no one asked for
    ],
)
def test_duplicated_header_name_is_refused_naming_it(tmp_path, header, name, times):
    path = tmp_path / "dup.csv"
    width = len(header.split(","))
    path.write_text(header + "\n" + "\n".join(",".join([str(k * DT)] * width) for k in range(3)) + "\n")
    with pytest.raises(
        ValueError, match=rf"^{re.escape(str(path))}: column '{name}' appears {times} in the header$"
    ):
        read_columns(path, ["beta_opov", "beta_fpov", "pc", "mr"])


def test_any_header_with_a_repeated_name_is_refused_property(tmp_path):
    """Property over random headers: a name given twice is refused and named, whatever the rest."""
    rng = np.random.default_rng(7)
    pool = ["t", "a", "b", "pc", "mr", "beta_opov", "x y", "é"]
    for trial in range(60):
        names = list(rng.choice(pool, size=rng.integers(1, 5), replace=False))
        dup = str(rng.choice(names))
        header = [*names]
        header.insert(int(rng.integers(0, len(header) + 1)), dup)
        path = tmp_path / f"h{trial}.csv"
        path.write_text(",".join(header) + "\n" + ",".join(["1"] * len(header)) + "\n", encoding="utf-8")
        with pytest.raises(ValueError, match=f"column '{re.escape(dup)}' appears twice in the header"):
            read_columns(path, [names[0]], dt=0.1)


def test_cli_validate_refuses_a_duplicated_header(tmp_path, capsys, model_path):
    data = _csv(tmp_path / "dup.csv", np.column_stack([_good(), _good(1)[:, 3]]), (*HEADER, "mr"))
    code = main(
        ["validate", "engine", "--model", str(model_path), "--data", str(data), "--out", str(tmp_path)]
    )
    _one_error_line(code, capsys.readouterr().err, r"dup\.csv: column 'mr' appears twice in the header")


def test_bom_file_reads_the_same_as_without(tmp_path):
    data = _good()
    plain = _csv(tmp_path / "plain.csv", data)
    bom = _csv(tmp_path / "bom.csv", data, bom=True)
    assert bom.read_bytes().startswith(b"\xef\xbb\xbf")
    columns = ["beta_opov", "beta_fpov", "pc", "mr"]
    a, dt_a = read_columns(plain, columns)
    b, dt_b = read_columns(bom, columns)
    np.testing.assert_array_equal(a, b)
    assert dt_a == dt_b == pytest.approx(DT)
    np.testing.assert_array_equal(a, data)


# --- degenerate validation records ----------------------------------------------------------------


def _degenerate(case: str) -> np.ndarray:
    data = _good()
    if case == "zero":
        data[:, 2] = 0.0
    elif case == "constant":
        data[:, 3] = 0.25
    elif case == "tiny":  # squares underflow to zero: SEE would divide by zero
        data[:, 3] = 1e-170 * np.sign(data[:, 3])
    elif case == "huge_output":
        data[5, 3] = 1e308
    elif case == "huge_input":
        data[:, 1] *= 1e200
    elif case == "nan":
        data[7, 2] = np.nan
    elif case == "inf":
        data[9, 0] = -np.inf
    return data


DEGENERATE = [
    ("zero", r"output 'pc' is zero throughout"),
    ("constant", r"output 'mr' is constant \(0\.25\)"),
    ("tiny", r"output 'mr' is zero throughout \(or too small to square\)"),
    ("huge_output", r"output 'mr' reaches 1e\+308: its squares overflow"),
    ("huge_input", r"input 'beta_fpov' reaches 1e\+198: its squares overflow"),
    ("nan", r"output 'pc' has NaN or inf at sample 7"),
    ("inf", r"input 'beta_opov' has NaN or inf at sample 9"),
]


@pytest.mark.parametrize(("case", "message"), DEGENERATE)
def test_check_validation_record_refuses_degenerate_records(case, message):
    data = _degenerate(case)
    with pytest.raises(ValueError, match=rf"^runs/x\.csv: {message}"):
        check_validation_record(
            data[:, :2], data[:, 2:], ("beta_opov", "beta_fpov"), ("pc", "mr"), "runs/x.csv"
        )


def test_check_validation_record_accepts_a_good_record_and_checks_shapes():
    data = _good()
    check_validation_record(data[:, :2], data[:, 2:], ("a", "b"), ("c", "d"))
    with pytest.raises(ValueError, match=r"^record: 2 input and 1 output names"):
        check_validation_record(data[:, :2], data[:, 2:], ("a", "b"), ("c",))
    with pytest.raises(ValueError, match="equal length"):
        check_validation_record(data[:, :2], data[:-1, 2:], ("a", "b"), ("c", "d"))


@pytest.mark.parametrize(("case", "message"), DEGENERATE)
def test_cli_validate_refuses_degenerate_records(tmp_path, capsys, model_path, case, message):
    good = _csv(tmp_path / "good.csv", _good())
    bad = _csv(tmp_path / f"{case}.csv", _degenerate(case))
    argv = ["validate", "engine", "--model", str(model_path), "--data", str(good), "--data", str(bad)]
    code = main([*argv, "--out", str(tmp_path / "v")])
    _one_error_line(code, capsys.readouterr().err, re.escape(str(bad)) + ": " + message)
    assert not (tmp_path / "v").exists()  # refused before anything is written


@pytest.mark.parametrize(("case", "message"), DEGENERATE[:3])
def test_cli_identify_refuses_a_degenerate_validation_record(tmp_path, capsys, case, message):
    data = _csv(tmp_path / "id.csv", _good(3))
    bad = _csv(tmp_path / f"{case}.csv", _degenerate(case))
    code = main(
        ["identify", "engine", "--data", str(data), "--validate", str(bad), "--out", str(tmp_path / "o")]
    )
    _one_error_line(code, capsys.readouterr().err, re.escape(str(bad)) + ": " + message)


def test_console_validate_refuses_an_overflowing_prediction_without_warnings(tmp_path, model_path):
    """Inputs just below the record limit: the model's prediction overflows, SEE would be inf."""
    data = _good()
    limit = 0.5 * np.sqrt(np.finfo(float).max / SAMPLES)
    data[:, :2] = np.sign(data[:, :2]) * 0.99 * limit
    path = _csv(tmp_path / "loud.csv", data)
    proc = subprocess.run(
        [sys.executable, "-m", "ssme_envs.cli", "validate", "engine", "--model", str(model_path),
         "--data", str(path), "--out", str(tmp_path / "v")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    _one_error_line(proc.returncode, proc.stderr, r"loud\.csv: the filter's see for output 'pc' is inf")


# --- records with the same file name --------------------------------------------------------------


def test_record_labels_are_distinct():
    paths = ["a/run.csv", "b/run.csv", "c/RUN.csv", "d/run_2.csv", "e/other.csv"]
    assert record_labels(paths) == ["run", "run_2", "RUN_3", "run_2_2", "other"]
    assert record_labels([]) == []


def test_cli_validate_keeps_records_with_the_same_file_name_apart(tmp_path, capsys, model_path):
    first = _csv(tmp_path / "a" / "run.csv", _good(1))
    second = _csv(tmp_path / "b" / "run.csv", 3 * _good(2))
    third = _csv(tmp_path / "c" / "other.csv", _good(4))
    out = tmp_path / "v"
    argv = ["validate", "engine", "--model", str(model_path), "--data", str(first), str(second)]
    assert main([*argv, "--data", str(third), "--out", str(out)]) == 0  # nargs and repeated --data
    printed = capsys.readouterr().out
    assert f"{first}: model SEE" in printed
    assert f"{second} (reported as run_2): model SEE" in printed
    assert f"{third}: model SEE" in printed
    report = (out / "report.md").read_text()
    rows = [line for line in report.splitlines() if line.startswith("| run") or line.startswith("| other")]
    assert [r.split("|")[1].strip() for r in rows] == ["run", "run", "run_2", "run_2", "other", "other"]
    assert rows[1] != rows[3]  # the two model rows are the two different records' scores
    for png in ("run.png", "run_2.png", "other.png"):
        assert f"]({png})" in report and (out / png).stat().st_size > 1000


# --- time base, unused columns, number syntax -----------------------------------------------------

COLUMNS = ["beta_opov", "beta_fpov", "pc", "mr"]


def _write(path, header, rows):
    path.write_text(header + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_epoch_style_time_column_is_uniform(tmp_path):
    """t = 1e9 + 0.04 k: each stamp is rounded to 1.2e-7 s, so steps read 0.0399999 to 0.0400001 s."""
    data = _good()
    t = 1e9 + DT * np.arange(SAMPLES)
    path = _write(
        tmp_path / "epoch.csv",
        ",".join(HEADER),
        [",".join(repr(float(v)) for v in r) for r in np.c_[t, data]],
    )
    assert np.ptp(np.diff(t)) > 1e-6 * DT  # irregular at the old tolerance
    got, dt = read_columns(path, COLUMNS)
    np.testing.assert_array_equal(got, data)
    assert dt == pytest.approx(DT, rel=1e-9)  # the fit over all stamps, not one rounded step
    assert read_columns(path, COLUMNS, dt=DT)[1] == dt  # a given dt agrees with it
    t[30:] += 0.01  # one step of 0.05 s among 0.04 s ones is still irregular there
    irregular = _write(
        tmp_path / "gap.csv", ",".join(HEADER), [",".join(repr(float(v)) for v in r) for r in np.c_[t, data]]
    )
    with pytest.raises(ValueError, match=r"gap\.csv: column 't' is not uniformly spaced"):
        read_columns(irregular, COLUMNS)


def _timed(path, t):
    """A record of the good data with time column ``t``, every value written exactly."""
    return _write(path, ",".join(HEADER), [",".join(repr(float(v)) for v in r) for r in np.c_[t, _good()]])


def test_time_stamps_too_coarse_for_their_steps_are_refused(tmp_path):
    t = 1e15 + 0.25 * np.arange(SAMPLES)  # floats near 1e15 are 0.125 s apart
    path = _timed(tmp_path / "coarse.csv", t)
    with pytest.raises(ValueError, match=r"coarse\.csv: column 't' cannot resolve its steps of 0\.25 s"):
        read_columns(path, COLUMNS)


@pytest.mark.parametrize(
    ("extra_header", "extra_cell"),
    [(",note", ",ok"), (",", ","), (",,,", ",,,"), (",note,", ",see log,")],
    ids=["text-column", "trailing-comma", "three-trailing-commas", "text-and-trailing"],
)
def test_columns_not_read_need_not_be_numbers(tmp_path, extra_header, extra_cell):
    data = _good()
    rows = [",".join(repr(float(v)) for v in r) + extra_cell for r in np.c_[DT * np.arange(SAMPLES), data]]
    path = _write(tmp_path / "extra.csv", ",".join(HEADER) + extra_header, rows)
    got, dt = read_columns(path, COLUMNS)
    np.testing.assert_array_equal(got, data)
    assert dt == pytest.approx(DT)


@pytest.mark.parametrize(
    ("column", "cell"),
    [("pc", "ok"), ("t", "soon"), ("mr", "1_0"), ("beta_opov", "-0_01"), ("t", "0_0")],
)
def test_non_numbers_in_columns_read_are_refused(tmp_path, column, cell):
    """Including Python's underscores, which float() reads (1_0 as 10) but CSV has no place for."""
    rows = [",".join(repr(float(v)) for v in r) for r in np.c_[DT * np.arange(SAMPLES), _good()]]
    cells = rows[3].split(",")
    cells[HEADER.index(column)] = cell
    rows[3] = ",".join(cells)
    path = _write(tmp_path / "bad.csv", ",".join(HEADER) + ",note", [r + ",x" for r in rows])
    with pytest.raises(ValueError, match=rf"bad\.csv: line 5, column '{column}': '{cell}' is not a number$"):
        read_columns(path, COLUMNS)


# --- sample times over a day ----------------------------------------------------------------------


def test_sample_time_over_a_day_is_refused(tmp_path):
    no_t = _write(
        tmp_path / "no_t.csv", ",".join(COLUMNS), [",".join(repr(float(v)) for v in r) for r in _good()]
    )
    assert read_columns(no_t, COLUMNS, dt=86_400.0)[1] == 86_400.0
    with pytest.raises(ValueError, match=r"no_t\.csv: sample time 1e\+300 s is over a day \(86400 s\)"):
        read_columns(no_t, COLUMNS, dt=1e300)
    slow = _timed(tmp_path / "slow.csv", 1e6 * np.arange(SAMPLES))
    with pytest.raises(ValueError, match=r"slow\.csv: sample time 1e\+06 s is over a day"):
        read_columns(slow, COLUMNS)


def test_sample_time_under_a_nanosecond_is_refused(tmp_path):
    no_t = _write(
        tmp_path / "no_t.csv", ",".join(COLUMNS), [",".join(repr(float(v)) for v in r) for r in _good()]
    )
    assert read_columns(no_t, COLUMNS, dt=1e-9)[1] == 1e-9
    with pytest.raises(
        ValueError, match=r"no_t\.csv: sample time 1e-300 s is under a nanosecond \(1e-09 s\)"
    ):
        read_columns(no_t, COLUMNS, dt=1e-300)
    fast = _timed(tmp_path / "fast.csv", 1e-12 * np.arange(SAMPLES))
    with pytest.raises(ValueError, match=r"fast\.csv: sample time 1e-12 s is under a nanosecond"):
        read_columns(fast, COLUMNS)


# --- the sample time of a time column ---------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    digits=st.integers(1, 999),
    exponent=st.integers(1, 6),
    rows=st.integers(2, 3000),
    written=st.sampled_from(["product", "fixed", "sum"]),
)
def test_a_decimal_step_reads_as_that_decimal(tmp_path_factory, digits, exponent, rows, written):
    """Stamps of a record taken every 0.04 s, however they were written (i * dt, fixed decimals or
    a running sum), give 0.04 s: the value a plant of the envs is then equal to."""
    dt = float(f"{digits}e-{exponent}")
    if dt < 1e-6 and written == "sum":  # a running sum of a tiny step drifts off uniform
        written = "product"
    k = np.arange(rows)
    if written == "product":
        cells = [repr(float(v)) for v in k * dt]
    elif written == "fixed":
        cells = [f"{v:.{exponent + 4}f}" for v in k * dt]
    else:
        cells = [repr(float(v)) for v in np.cumsum(np.r_[0.0, np.full(rows - 1, dt)])]
    path = _write(
        tmp_path_factory.mktemp("t") / "r.csv", "t,u,y", [f"{c},0.5,{i % 7}" for i, c in enumerate(cells)]
    )
    assert read_columns(path, ("u", "y"))[1] == dt


@pytest.mark.parametrize("dt", [1 / 30, 1 / 3000, 2 / 7])
def test_a_step_that_is_no_short_decimal_keeps_its_value(tmp_path, dt):
    path = _timed(tmp_path / "thirds.csv", dt * np.arange(SAMPLES))
    got = read_columns(path, COLUMNS)[1]
    assert got == pytest.approx(dt, rel=1e-10)
    assert read_columns(path, COLUMNS, dt=dt)[1] == got


def test_a_plant_read_from_stamps_takes_the_design_model_of_its_sample_time():
    """A plant whose dt carries a stamp's last bits (0.04 + 3.6e-17 s) is designed on as one of
    0.04 s; one of another sample time is refused with both times shown."""
    model = identified_model(100)
    near = gym.make("ssme_envs/EngineTracking-v0", plant=dataclasses.replace(model, dt=0.040000000000000036))
    assert near.unwrapped.task.design_model("identified").dt == DT
    other = gym.make("ssme_envs/EngineTracking-v0", plant=dataclasses.replace(model, dt=0.0400001))
    with pytest.raises(ValueError, match=r"design model has dt 0\.04 s but the env's plant 0\.0400001 s"):
        other.unwrapped.task.design_model("identified")


# --- files that are not regular files, or too large -----------------------------------------------


def _cli(argv: list[str], cwd) -> subprocess.CompletedProcess:
    """The console command in a child, so that a hang or a runaway read (the failures these tests
    catch) ends in a timeout or a MemoryError instead of taking the test run with it."""

    def bounded_memory():  # pragma: no cover - runs in the child
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))

    try:
        return subprocess.run(
            [sys.executable, "-m", "ssme_envs.cli", *argv], capture_output=True, text=True, check=False,
            cwd=cwd, timeout=60, preexec_fn=bounded_memory, env={**os.environ, "OMP_NUM_THREADS": "1"},
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail(f"ssme-envs {' '.join(argv)} did not end within 60 s")


@pytest.mark.skipif(not hasattr(os, "mkfifo") or sys.platform == "win32", reason="POSIX special files")
@pytest.mark.parametrize(
    ("special", "kind"),
    [("fifo", "a FIFO"), ("dev-zero", "a character device"), ("link-to-dev-zero", "a character device")],
)
def test_cli_refuses_special_files_as_records(tmp_path, model_path, special, kind):
    """A FIFO named like a record hung the reader; /dev/zero was read for gigabytes, then reported
    as out of memory. Both are refused up front, symlinks followed."""
    if special == "fifo":
        data = tmp_path / "x.csv"
        os.mkfifo(data)
    elif special == "dev-zero":
        data = Path("/dev/zero")
    else:
        data = tmp_path / "zero.csv"
        data.symlink_to("/dev/zero")
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    argv = ["validate", "engine", "--model", str(model_path), "--data", str(data), "--out", "v"]
    proc = _cli(argv, tmp_path)
    _one_error_line(
        proc.returncode, proc.stderr, rf"{re.escape(str(data))}: cannot read: not a regular file \({kind}\)$"
    )
    assert not (tmp_path / "v").exists()


def test_record_over_the_size_limit_is_refused_unread(tmp_path):
    path = tmp_path / "huge.csv"
    with path.open("wb") as fh:  # sparse: no disk or memory is spent on it unless it is read
        fh.truncate(MAX_CSV_BYTES + 1)
    with pytest.raises(ValueError, match=r"huge\.csv: larger than 1 GiB, the most a record may have$"):
        read_columns(path, COLUMNS)


def test_read_text_bounds_what_it_reads(tmp_path):
    path = tmp_path / "r.csv"
    path.write_bytes(b"\xef\xbb\xbft,a\n0,1\n")
    assert read_text(path) == "t,a\n0,1\n"
    assert read_text(path, max_bytes=11) == "t,a\n0,1\n"
    with pytest.raises(ValueError, match="larger than"):
        read_text(path, max_bytes=10)


# --- an identified model whose simulation of its own record overflows -------------------------------


@pytest.mark.parametrize("radius", [1.5, 2.0, 10.0])
def test_an_identified_model_whose_simulation_overflows_is_refused_by_name(radius):
    """identify_record's figures on its own record: a model unstable enough to overflow over the
    record gives a ValueError naming the figure, the output and the spectral radius, never an inf
    in model.fit (it used to be written there, and the CLI then failed on the JSON)."""
    from ssme_envs.identification.metrics import finite_validation

    model = identified_model(100)
    model = dataclasses.replace(model, A=model.A * (radius / model.spectral_radius()))
    data = _good()
    u, y = np.tile(data[:, :2], (40, 1)), np.tile(data[:, 2:], (40, 1))  # 2400 samples: radius^2400 overflows
    with pytest.raises(
        ValueError,
        match=rf"^the record: the model's see for output '\w+' is (inf|nan) .*radius {radius:.4g}\)$",
    ):
        finite_validation(model, u, y, "the record")


def test_a_negative_fit_is_said_with_what_it_means():
    """fit_warning on the packaged 100 % model: scaled to spectral radius 1.02 (its simulation over
    200 samples drifts: fit far below 0, computed here as NRMSE against a record of the stable
    model) the warning names the instability; stable, against an unrelated noise record (fit
    below 0), it points at the structure and method; on its own record (fit 100 %) no warning."""
    from ssme_envs.identification.metrics import fit_percent, fit_warning, model_prediction

    stable = identified_model(100)
    rng = np.random.default_rng(0)
    u = rng.choice([-0.01, 0.01], size=(200, 2))
    y = model_prediction(stable, u)
    unstable = dataclasses.replace(stable, A=stable.A * (1.02 / stable.spectral_radius()))
    fit = fit_percent(y, model_prediction(unstable, u))
    assert np.all(fit < 0)
    text = fit_warning(unstable, fit.tolist())
    assert re.fullmatch(r"warning: .* worse than the outputs' means \(pc .* %, mr .* %\): the model is "
                        r"unstable \(spectral radius 1\.02\).*one-step figures", text)  # fmt: skip
    noise = rng.standard_normal((200, 2))
    fit = fit_percent(noise, model_prediction(stable, u))
    assert np.all(fit < 0)
    assert re.search(r"--indices\) or try --method oe$", fit_warning(stable, fit.tolist()))
    assert fit_warning(stable, fit_percent(y, model_prediction(stable, u)).tolist()) is None


def _validate(model_path, data, out) -> int:
    return main(["validate", "engine", "--model", str(model_path), "--data", str(data), "--out", str(out)])


@pytest.mark.parametrize("samples", [2, 9])
def test_cli_validate_refuses_a_record_too_short_to_judge_the_model(tmp_path, capsys, model_path, samples):
    """The 4-state model on 2 or 9 samples: SEE and fit said 96 % of a 2-sample record; now refused
    below 2 (4 + 1) = 10 samples, naming the count needed (10 samples are judged)."""
    code = _validate(model_path, _csv(tmp_path / "short.csv", _good()[:samples]), tmp_path / "v")
    pattern = (
        rf"short\.csv: the record has {samples} samples; SEE and fit of a 4-state model need at least 10"
    )
    _one_error_line(code, capsys.readouterr().err, pattern)
    assert _validate(model_path, _csv(tmp_path / "enough.csv", _good()[:10]), tmp_path / "w") == 0


def test_a_one_row_record_is_refused_for_its_length_not_its_time_column(tmp_path, capsys, model_path):
    code = _validate(model_path, _csv(tmp_path / "one.csv", _good()[:1]), tmp_path / "v")
    pattern = r"one\.csv: the record has 1 sample\(s\): a sample time needs two"
    _one_error_line(code, capsys.readouterr().err, pattern)
