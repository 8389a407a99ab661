"""Atomic writes, run directories swapped in whole, and the lock of an output directory."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from ssme_envs.outputs import (
    MARKER,
    OutputError,
    atomic_write,
    directory_lock,
    run_directory,
    save_figure,
    write_text,
)


def _tree(root):
    """{relative path: bytes (files) or None (directories)} of everything under ``root``."""
    out = {}
    for base, dirs, files in os.walk(root):
        for name in dirs:
            out[os.path.relpath(os.path.join(base, name), root)] = None
        for name in files:
            path = os.path.join(base, name)
            with open(path, "rb") as fh:
                out[os.path.relpath(path, root)] = fh.read()
    return out


def _previous_run(path, text="old model"):
    path.mkdir(parents=True)
    (path / MARKER).write_text("{}")
    (path / "model.json").write_text(text)
    return _tree(path)


def test_atomic_write_replaces_whole_or_not_at_all(tmp_path):
    path = tmp_path / "model.json"
    write_text(path, "first\n")
    with pytest.raises(RuntimeError), atomic_write(path) as fh:
        fh.write("half of the seco")
        raise RuntimeError("killed")
    assert path.read_text() == "first\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]  # the temporary file is gone
    write_text(path, "second\n")
    assert path.read_text() == "second\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]


def test_atomic_write_honours_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o640


def test_atomic_write_onto_a_directory_fails_and_leaves_no_temporary(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(IsADirectoryError):
        write_text(tmp_path / "taken", "x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_atomic_write_refuses_a_special_file_and_writes_through_a_symlink(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(OutputError, match="is not a regular file"):
        write_text(fifo, "x")
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    with pytest.raises(OutputError, match="is not a regular file"):
        write_text("/dev/null", "x")  # not replaced, even by root
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    target, link = tmp_path / "target.md", tmp_path / "link.md"
    target.write_text("old")
    link.symlink_to(target)
    write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "link.md", "target.md"]


def test_save_figure_writes_a_png(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1])
    save_figure(fig, tmp_path / "f.png", dpi=50)
    plt.close(fig)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


def test_run_directory_swaps_the_new_run_in_and_drops_the_old(tmp_path):
    out = tmp_path / "run"
    _previous_run(out)
    (out / "stale.png").write_text("from the old run")
    with run_directory(out) as work:
        assert work.parent == tmp_path and work != out
        assert (out / "model.json").read_text() == "old model"  # untouched while the run builds
        write_text(work / "model.json", "new model")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "model.json"]  # one run's files only
    assert (out / "model.json").read_text() == "new model"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no lock, no leftovers


def test_a_failed_run_leaves_the_previous_one_and_nothing_else(tmp_path):
    out = tmp_path / "run"
    before = _previous_run(out)
    with pytest.raises(KeyboardInterrupt), run_directory(out) as work:
        write_text(work / "model.json", "new model")
        raise KeyboardInterrupt
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_failed_first_run_removes_the_parents_it_made(tmp_path):
    with pytest.raises(ValueError), run_directory(tmp_path / "a" / "b" / "run"):
        raise ValueError("bad input")
    assert list(tmp_path.iterdir()) == []


def test_a_foreign_directory_or_a_file_is_refused(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(OutputError, match="not empty and was not written by ssme-envs"):
        with run_directory(tmp_path / "mine"):
            pass
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "precious"
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        with run_directory(tmp_path / "file"):
            pass
    with run_directory(tmp_path / "empty") as work:  # an empty directory is taken
        write_text(work / "a", "1")
    assert (tmp_path / "empty" / "a").read_text() == "1"


def test_the_next_run_cleans_up_after_a_killed_one(tmp_path):
    out = tmp_path / "run"
    before = _previous_run(out)
    # killed while building: its directory stays; killed between the two renames of the swap:
    # the previous run is aside as .run.old-*, --out is gone
    (tmp_path / ".run.new-dead1").mkdir()
    (tmp_path / ".run.new-dead1" / ".model.json.1234.tmp").write_text('{"A": [[1')
    os.rename(out, tmp_path / ".run.old-dead2")
    with pytest.raises(RuntimeError), run_directory(out):
        assert _tree(out) == before  # put back before this run starts
        raise RuntimeError
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_held_lock_refuses_a_second_run_naming_the_holder(tmp_path):
    out = tmp_path / "run"
    before = _previous_run(out)
    with directory_lock(out) as lock:
        assert lock.read_text().strip() == str(os.getpid())
        with pytest.raises(OutputError, match=rf"{out} is in use .*pid {os.getpid()}, lock file"):
            with run_directory(out):
                pass
    assert _tree(out) == before
    assert not lock.exists()


def test_a_lock_held_by_another_process_is_refused(tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from pathlib import Path; "
         "from ssme_envs.outputs import directory_lock\n"
         "with directory_lock(Path(sys.argv[1])):\n print('held', flush=True); time.sleep(60)", str(out)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputError, match=f"pid {holder.pid}"), run_directory(out):
            pass
    finally:
        holder.kill()
        holder.wait()
    with run_directory(out) as work:  # its lock died with it
        write_text(work / "a", "1")
    assert (out / "a").exists()


def test_a_stale_lock_file_of_a_dead_process_is_taken_over(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)  # fmt: skip
    (tmp_path / ".run.lock").write_text(dead.stdout)
    with run_directory(tmp_path / "run") as work:
        assert (tmp_path / ".run.lock").read_text().strip() == str(os.getpid())
        write_text(work / "a", "1")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_stage_false_only_locks(tmp_path):
    out = tmp_path / "train"
    with run_directory(out, stage=False) as target:
        assert target == out and not out.exists()
        out.mkdir()
        (out / "policy.json").write_text("{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["train"]


def test_bench_refuses_a_special_file_before_it_measures(capsys, monkeypatch):
    from ssme_envs import bench
    from ssme_envs.cli import main

    monkeypatch.setattr(bench, "run_benchmark", lambda *a, **k: pytest.fail("measured before refusing"))
    args = ["bench", "--rounds", "1", "--sizes", "1", "--env", "ssme_envs/NozzleTVC-v0", "--out", "/dev/null"]
    assert main(args) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "error: /dev/null exists and is not a regular file: refusing to replace it"
    )


# --- the library's run functions keep their inputs out of the earlier run they replace ---------


def _record_and_model(where):
    from ssme_envs.identification.pipeline import default_experiment, write_record
    from ssme_envs.models import identified_model

    write_record(where / "r.csv", default_experiment(100)["identification"])
    identified_model(100).save(where / "m.json")


def _library_run(call, out):
    """(the call of a library run function reading an input inside ``out``, the input's name)."""
    from ssme_envs import pipelines

    record, model, run = out / "r.csv", out / "m.json", out / "run"
    if call == "identify_engine":
        return lambda: pipelines.identify_engine(out, record, indices=(2, 2)), "data"
    if call == "identify_nozzle":
        return lambda: pipelines.identify_nozzle(out, record, input_column="pc", output_column="mr"), "data"
    if call == "validate_engine":
        return lambda: pipelines.validate_engine(out, model, [record]), "model"
    if call == "evaluate_plant":
        env = "ssme_envs/EngineTracking-v0"
        return lambda: pipelines.evaluate_to(out, env, ["zero"], ["pc_step"], 1, plant=str(model)), "plant"
    spec = f"ppo:{run}"
    return lambda: pipelines.evaluate_to(
        out, "ssme_envs/NozzleTVC-v0", [spec], ["step"], 1
    ), f"controllers {spec}"


@pytest.mark.parametrize(
    "call", ["identify_engine", "identify_nozzle", "validate_engine", "evaluate_plant", "evaluate_policy"]
)
def test_a_library_run_refuses_inputs_inside_the_earlier_run_it_would_replace(tmp_path, call):
    import re
    import shutil

    from agents.sb3 import shipped_policy

    out = tmp_path / "out"
    _previous_run(out)
    _record_and_model(out)
    shutil.copytree(shipped_policy("ssme_envs/NozzleTVC-v0"), out / "run")
    before = _tree(out)
    run, name = _library_run(call, out)
    message = rf"^{re.escape(name)} {re.escape(str(out))}/\S+ lies in out_dir {re.escape(str(out))}, which"
    with pytest.raises(OutputError, match=message):
        run()
    assert _tree(out) == before


def test_a_dangling_symlink_as_the_output_is_refused_and_a_live_one_followed(tmp_path):
    """A link to a missing directory: the run followed it and created the directory and its
    parents wherever it pointed (outside the folder named); now refused by name. A link to an
    existing directory is written through, as before."""
    away = tmp_path / "away" / "deeper"
    link = tmp_path / "out"
    link.symlink_to(away)
    with pytest.raises(OutputError, match=r"out: a symbolic link to .*deeper, which does not exist"):
        with run_directory(link):
            pass
    assert not (tmp_path / "away").exists()
    away.mkdir(parents=True)
    with run_directory(link) as work:
        write_text(work / "a", "1")
    assert (away / "a").read_text() == "1"
