"""Train the PPO policies of experiments/configs and ship those of SHIP with the package.

Each config trains on this machine's CPU through the SB3 adapter (VecNormalize, the best
evaluation kept) into experiments/runs/<config>/ (policy.json, policy.safetensors,
normalization.json: no pickle); the policies of SHIP (each env's, trained on its full truth) are
copied into agents/policies/<name>/. Every run is then
evaluated by the harness beside the LQ servo (or the scheduled one) on the plant it was trained
for and on the full truth. The policy trained on EngineTracking's identified model is shipped too
(the sim-to-real comparison), NozzleTVC's fine-tuned on drawn plants (after the nominal one,
which it starts from), and the residual policies over a classical design (``*_residual``, and
EngineTracking's ``*_residual_quiet``, trained with its correction penalized: the "PPO cost"
column is the residual policy's with its base). Writes experiments/results/rl_training.md, keeping
the LauncherPitch section experiments/launcher_rl.py appends unless a LauncherPitch config was
retrained (then rerun launcher_rl.py).

    python experiments/train_policies.py [--evaluate-only] [config names ...]

--evaluate-only re-evaluates the runs already in experiments/runs/ without training (a shipped
policy's copy in agents/policies/ where its run is not there).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from agents import parse_controller
from agents.sb3 import load_config, train
from ssme_envs.evaluation import SCENARIOS, evaluate
from ssme_envs.outputs import write_text
from ssme_envs.script_options import script_parser

HERE = Path(__file__).resolve().parent
SHIP = {
    "ppo_engine_tracking": "EngineTracking-v0",
    "ppo_engine_tracking_identified": "EngineTracking-v0-identified",
    "ppo_engine_throttle": "EngineThrottle-v0",
    "ppo_nozzle_tvc": "NozzleTVC-v0",
    "ppo_nozzle_tvc_spread": "NozzleTVC-v0-spread",  # after ppo_nozzle_tvc: it starts from that policy
    "ppo_launcher_pitch": "LauncherPitch-v0",
    # residual policies over a classical design (agents/residual.py)
    "ppo_engine_tracking_residual": "EngineTracking-v0-residual",
    "ppo_engine_tracking_residual_quiet": "EngineTracking-v0-residual_quiet",
    "ppo_engine_throttle_residual": "EngineThrottle-v0-residual",
    "ppo_nozzle_tvc_residual": "NozzleTVC-v0-residual",
    "ppo_launcher_pitch_residual": "LauncherPitch-v0-residual",
}
# the scenarios of the plant each config trains on (then the full truth's)
PLANT = {
    "ppo_engine_tracking": ("noise",),
    "ppo_engine_tracking_nominal": ("nominal",),
    "ppo_engine_tracking_identified": ("design_plant",),
    "ppo_engine_throttle": ("mission",),
    "ppo_nozzle_tvc": ("random_steps", "step", "sine_sweep", "attitude"),
    "ppo_nozzle_tvc_mixed": ("random_steps", "step", "sine_sweep", "attitude"),
    "ppo_nozzle_tvc_spread": ("random_steps", "step", "sine_sweep", "attitude"),
    "ppo_launcher_pitch": ("random_steps", "step", "attitude", "linear_nozzle"),
    "ppo_engine_tracking_residual": ("noise", "pc_step", "mr_step"),
    "ppo_engine_tracking_residual_quiet": ("noise", "pc_step", "ramp"),
    "ppo_engine_throttle_residual": ("mission", "mission_nonlinear"),
    "ppo_nozzle_tvc_residual": ("random_steps", "step", "sine_sweep", "attitude", "sine_sweep_strong"),
    "ppo_launcher_pitch_residual": ("random_steps", "step", "attitude", "linear_nozzle"),
}
TRUTH = {"ssme_envs/EngineTracking-v0": "noise", "ssme_envs/EngineThrottle-v0": "mission",
         "ssme_envs/NozzleTVC-v0": "random_steps", "ssme_envs/LauncherPitch-v0": "random_steps"}  # fmt: skip
# the LQ servo designed on the identified model (as users would), and a second reference: on
# EngineTracking the reward's LQ-optimal tracker on the true linear model (the physical limit)
BASELINES = {"ssme_envs/EngineTracking-v0": ("lqi", "lq:truth"),
             "ssme_envs/EngineThrottle-v0": ("scheduled", "scheduled:truth"),
             "ssme_envs/NozzleTVC-v0": ("lqi", "hysteresis"),
             "ssme_envs/LauncherPitch-v0": ("pid", "robust")}  # fmt: skip


def main(names: list[str], evaluate_only: bool = False) -> None:
    header = [
        "# PPO training and evaluation",
        "",
        "Command: `python experiments/train_policies.py`. Training on this machine's CPU (2 cores); cost = "
        "minus the return, mean over 50 evaluation episodes (seed 0, the harness's), the baselines on the "
        "same episodes: the LQ servo designed on the identified model (`lqi`, scheduled in power on "
        "EngineThrottle), and `lq:truth`, the reward's LQ-optimal tracker on the true linear model (the "
        "physical limit on the nominal plant), the scheduled servo on the truth's linear models, or the "
        "LQ servo with the hysteresis compensation on NozzleTVC.",
        "",
        "| config | env | steps | wall-clock s | steps/s | scenario | PPO cost | baseline cost (PPO / it) "
        "| second baseline |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    trained_launcher = False
    for name in names:
        config = load_config(HERE / "configs" / f"{name}.toml")
        out = HERE / "runs" / name
        if evaluate_only and not out.exists() and name in SHIP:  # a fresh clone: runs/ is not shipped
            out = HERE.parent / "agents" / "policies" / SHIP[name]
        if evaluate_only:
            summary = json.loads((out / "training.json").read_text())
        else:
            summary = train(config, out)
        env_id = config["env"]
        trained_launcher |= not evaluate_only and env_id == "ssme_envs/LauncherPitch-v0"
        if name in SHIP and not evaluate_only:
            target = HERE.parent / "agents" / "policies" / SHIP[name]
            target.mkdir(parents=True, exist_ok=True)
            for file in ("policy.json", "policy.safetensors", "normalization.json", "config.toml",
                         "training.json"):  # fmt: skip
                shutil.copy(out / file, target / file)
        baselines = BASELINES[env_id]
        for scenario in dict.fromkeys([*PLANT[name], TRUTH[env_id]]):
            assert scenario in SCENARIOS[env_id]
            factories = {"ppo": parse_controller(f"ppo:{out}", env_id)}  # with its base if residual
            factories |= {spec: parse_controller(spec, env_id) for spec in baselines}
            results = evaluate(env_id, factories, [scenario], episodes=50)[scenario]
            ppo = results["ppo"]["cost_mean"]
            costs = {spec: results[spec]["cost_mean"] for spec in baselines}
            compared = " | ".join(f"{spec} {cost:.3f} ({ppo / cost:.2f})" for spec, cost in costs.items())
            rows.append(
                f"| {name} | {env_id} | {summary['steps']:,} | {summary['seconds']:.0f} | "
                f"{summary['steps_per_s']:,.0f} | {scenario} | {ppo:.3f} | {compared} |"
            )
            print(rows[-1], flush=True)
    path = HERE / "results" / "rl_training.md"
    tail: list[str] = []
    if path.exists():  # keep the rows of the configs not rerun this time, and the sections after
        lines = path.read_text().splitlines()[len(header) :]
        cut = next((i for i, line in enumerate(lines) if line.startswith("## ")), len(lines))
        tail = ["", *lines[cut:]] if cut < len(lines) else []  # launcher_rl.py's section
        if tail and trained_launcher:  # that section describes the policies retrained now
            tail = []
            print("the LauncherPitch section is left out: run experiments/launcher_rl.py", flush=True)
        old = [row for row in lines[:cut] if row.startswith("| ")]
        rows += [row for row in old if row.split("|")[1].strip() not in names]
    rows.sort(key=lambda row: list(PLANT).index(row.split("|")[1].strip()))
    write_text(path, "\n".join(header + rows + tail) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    parser = script_parser(__doc__.split("\n\n")[0])
    parser.add_argument(
        "names", nargs="*", metavar="CONFIG", help=f"configs to run (default: all): {', '.join(PLANT)}"
    )
    parser.add_argument(
        "--evaluate-only", action="store_true", help="re-evaluate the runs in experiments/runs/, no training"
    )
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(PLANT))
    if unknown:
        parser.error(f"unknown CONFIG {', '.join(unknown)}; valid: {', '.join(PLANT)}")
    main(args.names or list(PLANT), args.evaluate_only)
