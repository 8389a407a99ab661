"""Bad command-line options of the scripts in experiments/: exit code 2 and one line ``error: ...``
on stderr that names the option and the value, no traceback, before any work (so each run takes
about as long as the script's imports); and the helpers of :mod:`ssme_envs.script_options` behind it.
The scripts run in subprocesses side by side (one per CPU), started when the first case needs them."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ssme_envs.cli_checks import check_episodes, integer, number
from ssme_envs.script_options import (
    comma_choices,
    episodes_within_memory,
    float_within,
    int_within,
    output_file,
    script_parser,
)

ROOT = Path(__file__).resolve().parents[1]
Case = tuple[str, tuple[str, ...], str]  # script, arguments, the option the error names
BOGUS = ("--bogus",)  # an unknown option: argparse's own error (scripts with quick imports only)
# script -> (arguments, the option the error names); {missing}, {file}, {dir}, {fifo} (a named
# pipe: written to, it would hang the script at its end), {slash} (a new path ending in "/", which
# names a directory): paths made per run.
# A run costs the script's imports (about 1 s; bench_ppo's torch 3 s): a few cases each.
CASES: dict[str, list[tuple[tuple[str, ...], str]]] = {
    "bench_engine_identification": [(("--repeats", "0"), "--repeats"), (("--repeats", "2.5"), "--repeats")],
    "bench_nozzle_identification": [
        (("--repeats", "-1"), "--repeats"),
        (("--workers", "0"), "--workers"),
        (("--workers", "100000"), "--workers"),
    ],
    "bench_ppo": [(("--steps", "0"), "--steps"), (("--rounds", "0"), "--rounds")],
    "bench_subspace": [(("--repeats", "0"), "--repeats"), (("--systems", "-1"), "--systems")],
    "bouc_wen_correction_coverage": [(("--seeds", "0"), "--seeds")],
    "engine_uncertainty_coverage": [
        (("--seeds", "0"), "--seeds"),
        (("--levels", "100,"), "--levels"),
        (("--methods", "mle"), "--methods"),
        (("--noise", "nan"), "--noise"),
        (("--noise", "0"), "--noise must be a number above 0"),  # noise-free intervals cover nothing
        (("--indices", "0,2"), "--indices"),
        (("--indices", "2"), "--indices"),
    ],
    "import_time": [(("--rounds", "0"), "--rounds"), (("--rounds", "x"), "--rounds"), (BOGUS, "--bogus")],
    "learned_vs_classical": [
        (("--episodes", "0"), "--episodes"),
        (("--episodes", "1000000000000000"), "--episodes"),
    ],
    "make_design_models": [(("--only", "foo"), "--only")],
    "nozzle_compensation_study": [
        (("--episodes", "-1"), "--episodes"),
        (("--episodes", "1000000000000000"), "--episodes"),
    ],
    "nozzle_uncertainty_coverage": [
        (("--seeds", "0"), "--seeds"),
        (("--replicates", "9"), "--replicates"),
        (("--bouc-wen-seeds", "-1"), "--bouc-wen-seeds"),
        (("--workers", "0"), "--workers"),
        (("--acquisitions", ""), "--acquisitions"),
        (("--out", "{missing}"), "--out"),
        (("--out", "{file}"), "--out"),
        (("--out", "{dir}"), "--out"),
        (("--out", "{fifo}"), "--out"),
    ],
    "nozzle_coloured_noise": [(("--seeds", "1"), "--seeds")],
    "readme_figures": [
        (("--episodes", "0"), "--episodes"),
        (("--episodes", "1000000000000000"), "--episodes"),
    ],
    "robustness_study": [(("--plants", "0"), "--plants")],
    "short_record_structure": [(("--seeds", "0"), "--seeds"), (("--methods", "mle"), "--methods")],
    "short_record_subspace": [(("--seeds", "0"), "--seeds")],
    "slow_mode_coverage": [
        (("--seeds", "0"), "--seeds"),
        (("--noise", "0"), "--noise"),
        (("--noise", "nan"), "--noise"),
    ],
    "structure_walk": [(("--seeds", "0"), "--seeds"), (("--first", "-1"), "--first")],
    "subspace_order": [(("--seeds", "0"), "--seeds"), (("--seeds", "x"), "--seeds")],
    "speed_limits": [
        (("--rounds", "0"), "--rounds"),
        (("--rounds", "101"), "--rounds"),
        (("--rounds",), "--rounds"),
        (BOGUS, "--bogus"),
    ],
    "train_policies": [(("no_such_config",), "CONFIG")],
    "weak_mode_structure": [
        (("--seeds", "0"), "--seeds"),
        (("--out", "{missing}"), "--out"),
        (("--seeds", "1", "--out", "{fifo}"), "--out"),
        (("--seeds", "1", "--out", "{dir}"), "--out"),
        (("--seeds", "1", "--out", "{slash}"), "--out"),
    ],
}
RUNS = [
    pytest.param((script, args, option), id=f"{script}:{' '.join(args)}")
    for script, cases in CASES.items()
    for args, option in cases
]


def _run(script: str, args: tuple[str, ...]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(ROOT / "experiments" / f"{script}.py"), *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def run_case(request, tmp_path_factory) -> Iterator[Callable[[Case], subprocess.CompletedProcess[str]]]:
    """The finished run of a case. The runs of the selected cases start together, one per CPU."""
    tmp = tmp_path_factory.mktemp("out")
    (tmp / "a_file").write_text("")
    os.mkfifo(tmp / "fifo")
    paths = {
        "missing": str(tmp / "missing" / "x.md"),
        "file": str(tmp / "a_file" / "x.md"),
        "dir": str(tmp),
        "fifo": str(tmp / "fifo"),
        "slash": str(tmp / "new") + "/",
    }
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        futures: dict[Case, Future] = {}

        def start(case: Case) -> Future:
            if case not in futures:
                futures[case] = pool.submit(_run, case[0], tuple(a.format(**paths) for a in case[1]))
            return futures[case]

        for item in request.session.items:
            params = getattr(getattr(item, "callspec", None), "params", {})
            if item.module is request.module and "case" in params:
                start(params["case"])
        yield lambda case: start(case).result()
        pool.shutdown(cancel_futures=True)


@pytest.mark.parametrize("case", RUNS)
def test_bad_option_is_one_error_line(run_case, case: Case) -> None:
    run = run_case(case)
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and "usage:" not in run.stderr
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and lines[0][len("error: ") :].strip(), lines
    assert case[2] in lines[0]  # the option
    assert run.args[-1] in lines[0]  # the value, as given (the option itself when there is none)
    assert run.stdout == ""  # no work started


def test_speed_limits_message_is_kept(run_case) -> None:
    """speed_limits.py's --rounds message as it was before the shared helper."""
    run = run_case(("speed_limits", ("--rounds", "0"), "--rounds"))
    assert run.stderr == "error: --rounds must be within 1-100, got 0\n"


def test_every_script_with_options_is_covered() -> None:
    """Each script with options is run above and builds its parser with script_parser (so that
    argparse's own errors, such as an unknown option, are one line too)."""
    texts = {p.stem: p.read_text() for p in (ROOT / "experiments").glob("*.py")}
    with_options = {name for name, text in texts.items() if "add_argument" in text}
    assert with_options == set(CASES)
    for name in with_options:
        assert "script_parser(" in texts[name] and "ArgumentParser" not in texts[name], name


def test_every_script_refuses_arguments_it_does_not_take() -> None:
    """Every script's command line goes through script_parser, those without options too: a
    stray argument (or --help) does not start a script's whole run and rewrite its records."""
    for path in (ROOT / "experiments").glob("*.py"):
        text = path.read_text()
        if 'if __name__ == "__main__":' in text:
            assert "script_parser(" in text, path.name
    run = _run("engine_noise_study", BOGUS)
    assert (run.returncode, run.stdout) == (2, "")
    assert run.stderr == "error: unrecognized arguments: --bogus\n"


def test_coverage_script_reports_seeds_without_a_model_to_count() -> None:
    """engine_uncertainty_coverage.py on data the identifier refuses (noise as large as the
    outputs' spread) and with a model whose indices are not the true ones (given as (3, 2): the
    structure search no longer misses them on these records): a row each, with the count and no
    coverage, where the script raised a traceback."""
    runs = [
        _run(
            "engine_uncertainty_coverage",
            ("--noise", noise, "--seeds", "1", "--levels", "70", "--methods", how, *given),
        )
        for noise, how, given in (("1.0", "iv", ()), ("0.3", "ls", ("--indices", "3,2")))
    ]
    assert [r.returncode for r in runs] == [0, 0], [r.stderr[-500:] for r in runs]
    assert "| 70 | iv | 0/1 (1 refused) | - | - |" in runs[0].stdout.splitlines()
    assert "| 70 | ls | 0/1 | - | - |" in runs[1].stdout.splitlines()


# ------------------------------------------------------------------ the helpers, in this process


def _parse(parser: argparse.ArgumentParser, argv: list[str], capsys) -> str:
    """The one line a parser's error prints (asserting exit code 2 and nothing else)."""
    with pytest.raises(SystemExit) as exit_:
        parser.parse_args(argv)
    assert exit_.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and err.endswith("\n") and err.count("\n") == 1 and err.startswith("error: "), err
    return err.rstrip("\n")


def _demo_parser() -> argparse.ArgumentParser:
    parser = script_parser("demo")
    parser.add_argument("--rounds", type=int_within(1, 100), default=5)
    parser.add_argument("--count", type=int, default=1)
    parser.add_argument("--only", choices=("engine", "nozzle"))
    return parser


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["--rounds", "0"], "error: --rounds must be within 1-100, got 0"),
        (["--rounds", "x"], "error: --rounds must be an integer within 1-100, got 'x'"),
        (["--rounds"], "error: --rounds: expected one argument"),
        (["--count", "1.5"], "error: --count: invalid int value: '1.5'"),
        (["--only", "z"], "error: --only: invalid choice: 'z' (choose from 'engine', 'nozzle')"),
        (["--bogus", "1"], "error: unrecognized arguments: --bogus 1"),
    ],
)
def test_script_parser_errors_are_one_line(capsys, argv, line) -> None:
    assert _parse(_demo_parser(), argv, capsys) == line


def test_script_parser_error_call_and_good_arguments(capsys) -> None:
    parser = _demo_parser()
    assert parser.parse_args(["--rounds", "100", "--only", "engine"]).rounds == 100
    assert parser.parse_args([]).rounds == 5
    with pytest.raises(SystemExit) as exit_:
        parser.error("CONFIG: two\nlines")
    assert exit_.value.code == 2
    assert capsys.readouterr().err == "error: CONFIG: two lines\n"


@given(
    low=st.integers(-1000, 1000),
    span=st.none() | st.integers(0, 1000),
    value=st.integers(-3000, 3000),
)
def test_int_within_accepts_exactly_its_range(low: int, span: int | None, value: int) -> None:
    high = None if span is None else low + span
    convert = int_within(low, high)
    if low <= value and (high is None or value <= high):
        assert convert(str(value)) == value
        return
    with pytest.raises(argparse.ArgumentTypeError) as error:
        convert(str(value))
    message = str(error.value)
    want = f"at least {low}" if high is None else f"within {low}-{high}"
    assert message == f"must be {want}, got {value}"


@given(text=st.text(max_size=12))
def test_int_within_refuses_non_integers(text: str) -> None:
    try:
        int(text)
    except ValueError:
        with pytest.raises(argparse.ArgumentTypeError, match="must be an integer within 0-9"):
            int_within(0, 9)(text)
    else:
        assert int_within(-(10**13), 10**13)(text) == int(text)


@given(value=st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=8))
def test_float_within_accepts_finite_numbers_in_range(value: float | str) -> None:
    text = repr(value) if isinstance(value, float) else value
    try:
        number = float(text)
    except ValueError:
        number = float("nan")
    for convert, high in ((float_within(0.0, 1.0), 1.0), (float_within(-2.5), None)):
        low = 0.0 if high is not None else -2.5
        if number == number and abs(number) != float("inf") and low <= number <= (high or float("inf")):
            assert convert(text) == number
        else:
            with pytest.raises(argparse.ArgumentTypeError, match="must be a number"):
                convert(text)
    above = float_within(0.0, 1.0, above=True)  # the same, 0 itself refused
    if number == number and 0.0 < number <= 1.0:
        assert above(text) == number
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="must be a number above 0 and at most 1"):
            above(text)


@given(items=st.lists(st.sampled_from(["iv", "ls", " ls ", "", "x", "IV"]), min_size=1, max_size=4))
def test_comma_choices_accepts_only_known_items(items: list[str]) -> None:
    text = ",".join(items)
    convert = comma_choices(("iv", "ls"))
    if all(item.strip() in ("iv", "ls") for item in items):
        assert convert(text) == ",".join(item.strip() for item in items)
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=r"must be a comma-separated list of iv, ls"):
            convert(text)


def test_output_file(tmp_path: Path) -> None:
    (tmp_path / "a_file").write_text("")
    assert output_file(str(tmp_path / "x.md")) == tmp_path / "x.md"
    assert output_file(str(tmp_path / "a_file")) == tmp_path / "a_file"  # replaced when written
    for bad, why in [
        (tmp_path, "must be a file"),
        (tmp_path / "missing" / "x.md", "does not exist"),
        (tmp_path / "a_file" / "x.md", "is not a directory"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=why):
            output_file(str(bad))


def test_output_file_refuses_special_files_and_directory_names(tmp_path: Path, capsys) -> None:
    """A FIFO (a script writing its record into one would hang at its end), a link to one, a
    device, and a path that names a directory by its form (a trailing "/", "/." or "/..", which
    Path() drops) are refused with the path given; nothing is left in the directory."""
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link").symlink_to(tmp_path / "fifo")
    (tmp_path / "a_file").write_text("kept")
    before = sorted(tmp_path.iterdir())
    refused = {
        tmp_path / "fifo": "not a regular file",
        tmp_path / "link": "not a regular file",
        Path(os.devnull): "not a regular file",
        f"{tmp_path / 'new'}/": "names a directory",
        f"{tmp_path / 'a_file'}/": "names a directory",
        f"{tmp_path / 'new'}/.": "names a directory",
        f"{tmp_path / 'new'}/..": "names a directory",
        tmp_path: "must be a file, got the directory",
    }
    for bad, why in refused.items():
        with pytest.raises(argparse.ArgumentTypeError, match=why) as error:
            output_file(str(bad))
        assert repr(str(bad)) in str(error.value) and "\n" not in str(error.value)
    assert sorted(tmp_path.iterdir()) == before and (tmp_path / "a_file").read_text() == "kept"
    assert output_file(str(tmp_path / "new")) == tmp_path / "new"
    assert not (tmp_path / "new").exists()  # checked, not created
    parser = script_parser("demo")
    parser.add_argument("--out", type=output_file)
    fifo = str(tmp_path / "fifo")
    line = _parse(parser, ["--out", fifo], capsys)
    assert line.startswith(f"error: --out must be a file this script can write, got {fifo!r} (")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in a read-only directory")
def test_output_file_refuses_a_directory_it_cannot_write_in(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    try:
        with pytest.raises(argparse.ArgumentTypeError, match="cannot write in"):
            output_file(str(locked / "x.md"))
    finally:
        locked.chmod(0o755)


def test_episodes_within_memory_holds_to_the_evaluate_commands_check() -> None:
    """The scripts' --episodes and ``ssme-envs evaluate --episodes`` refuse the same counts with
    the same message: a count the command's check refuses, and one it takes."""
    plan = {"ssme_envs/NozzleTVC-v0": 6}
    convert = episodes_within_memory(lambda: plan)
    assert convert("3") == 3
    with pytest.raises(ValueError) as refused:
        check_episodes(10**15, plan)
    with pytest.raises(argparse.ArgumentTypeError) as given_text:
        convert(str(10**15))
    assert str(given_text.value) == str(refused.value)
    assert str(refused.value).startswith(f"--episodes {10**15} needs about ")
    with pytest.raises(argparse.ArgumentTypeError, match="must be at least 1, got 0"):
        convert("0")


@given(st.floats(allow_nan=False, allow_infinity=False), st.sampled_from(["{!r}", "{:e}", "{:.17g}", "{:f}"]))
def test_number_options_read_decimal_text_as_float_does(value, form):
    text = form.format(value)
    assert number(text) == float(text)


@given(st.integers(), st.integers(min_value=1, max_value=30))
def test_options_refuse_python_literal_forms_that_a_csv_would_not_hold(value, cut):
    digits = str(abs(value)) + "0"
    assert integer(str(value)) == value
    spaced = digits[: cut % len(digits) or 1] + "_" + digits[cut % len(digits) or 1 :]
    for text in (spaced, "0x" + digits, "\u0663" + digits):  # \u0663: an Arabic-Indic digit
        with pytest.raises(ValueError):
            integer(text)
        with pytest.raises(ValueError):
            number(text)
