"""The README's controller and RL figures against experiments/results/readme_figures.md, and
the script's computation of one figure against the table."""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "experiments" / "results" / "readme_figures.md"
# a ratio as the README writes them ("0.91x"); no other README number ends in x
RATIO = re.compile(r"(?<![\w.])\d+(?:\.\d+)?x\b")


def _table() -> dict[str, str]:
    rows = re.findall(r"^\| (\w+) \| ([^|]+?) \| [^|]+ \|$", TABLE.read_text(), flags=re.M)
    return {key: value for key, value in rows if key != "figure"}


def _readme_ratios() -> list[str]:
    text = re.sub(r"```.*?```", "", (ROOT / "README.md").read_text(), flags=re.S)  # code blocks
    return RATIO.findall(text)


def test_every_ratio_in_the_readme_is_in_the_table():
    figures = _table()
    ratios = _readme_ratios()
    assert ratios, "the README quotes no ratio: update this test"
    unbacked = [r for r in ratios if r not in figures.values()]
    assert not unbacked, f"README ratios not in {TABLE.name}: {unbacked}"


def test_every_figure_of_the_table_is_quoted_as_written():
    readme = (ROOT / "README.md").read_text()
    figures = _table()
    assert len(figures) == 11
    for key, value in figures.items():
        if value.endswith("x"):
            assert value in _readme_ratios(), key
        else:  # the compensation's cut: "cuts it by N %"
            assert f"cuts it by {value}" in re.sub(r"\s+", " ", readme), key


def test_the_script_reproduces_the_strong_joint_figures():
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        import readme_figures
    finally:
        sys.path.pop(0)
    episodes = int(re.search(r"--episodes (\d+)", TABLE.read_text())[1])
    nozzle = readme_figures.NOZZLE
    runs = {nozzle: (["lqi", "hysteresis"], ["sine_sweep_strong", "sine_sweep_strong_linear"])}
    results = readme_figures.evaluations(episodes, runs)
    figures = _table()
    for key in ("strong_lqi_over_linear", "strong_compensation_cut"):
        assert readme_figures.FIGURES[key][1](results) == figures[key]


def test_the_readme_counts_of_learned_within_the_bar_are_the_recorded_ones():
    """The README's "N of M" per env and in total, against experiments/results/learned_vs_classical.md."""
    recorded = (ROOT / "experiments" / "results" / "learned_vs_classical.md").read_text()
    line = re.search(r"within 1\.10x the best classical design: (.*)\.", recorded)[1]
    counts = re.findall(r"(\w+)-v0 (\d+) of (\d+)", line)
    assert len(counts) == 4
    readme = re.sub(r"\s+", " ", (ROOT / "README.md").read_text())
    for env, met, total in counts:
        assert f"{env} {met} of {total}" in readme, env
    met, total = sum(int(c[1]) for c in counts), sum(int(c[2]) for c in counts)
    assert f"best classical design on {met} of {total}" in readme
