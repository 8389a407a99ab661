"""What reads the env catalogue has an entry for every env of it, names only its ids, and the
README's env table and controller lists say what the catalogue and ``agents.CONTROLLERS`` say."""

import re
import sys
from pathlib import Path

import pytest

from agents import CONTROLLERS, POLICY_VARIANTS, controller_names
from agents.sb3 import SHIPPED
from ssme_envs.envs import catalogue
from ssme_envs.evaluation import SCENARIOS, TRACKED, layout_of
from ssme_envs.main_report import REPORT_PLAN
from ssme_envs.pipelines import report_plan

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def catalogue_table() -> list[str]:
    """The README's table of the envs, from the catalogue."""
    lines = ["| env | observation columns, in order (unit) | actions | steps |", "|---|---|---|---|"]
    for env_id, entry in catalogue.ENVS.items():
        obs = entry.observation
        columns = ", ".join(f"`{name}` ({unit})" for name, unit in zip(obs.names, obs.units, strict=True))
        actions = ", ".join(entry.action_names)
        lines.append(f"| `{env_id}` | {columns} | {actions} | {entry.max_episode_steps} |")
    return lines


def test_every_env_has_scenarios_a_layout_a_report_plan_and_a_designed_controller():
    ids = set(catalogue.ENVS)
    assert set(SCENARIOS) == ids and set(TRACKED) == ids and set(REPORT_PLAN) == ids
    assert list(report_plan(learned=False)) == list(catalogue.ENVS)
    for env_id, entry in catalogue.ENVS.items():
        layout = layout_of(env_id)  # every tracked output's columns resolve in the env's layout
        assert layout.actuators == entry.action_names
        assert [name for name in controller_names(env_id) if name != "zero"], env_id


def test_only_catalogue_ids_are_named():
    ids = set(catalogue.ENVS)
    for name, (_, env_ids, _) in CONTROLLERS.items():
        assert set(env_ids) <= ids, name
    trained_on = ("identified", *POLICY_VARIANTS)  # the suffixes of policies not trained on the truth
    env_names = {n.rsplit("-", 1)[0] if n.rsplit("-", 1)[-1] in trained_on else n for n in SHIPPED}
    assert {f"ssme_envs/{name}" for name in env_names} <= ids
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        train_policies = pytest.importorskip("train_policies")
    finally:
        sys.path.remove(str(ROOT / "experiments"))
    assert set(train_policies.TRUTH) <= ids and set(train_policies.BASELINES) <= ids
    assert set(train_policies.SHIP.values()) == set(SHIPPED)  # what it ships is what agents load


def test_readme_lists_the_catalogue():
    expected = "\n".join(catalogue_table())
    assert expected in README, f"README.md's env table should read:\n{expected}"


def test_readme_lists_each_envs_controllers():
    for env_id in catalogue.ENVS:
        short = env_id.split("/")[-1].removesuffix("-v0")
        listed = re.search(rf"{short} `([^`]*)`", README)
        assert listed, f"README.md lists no controllers for {short}"
        assert sorted(listed[1].split(", ")) == sorted(controller_names(env_id)), short
