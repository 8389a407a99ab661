"""PPO throughput through the SB3 adapter, against PPO on CartPole-v1 in the same run.

PPO with the shipped policies' settings (experiments/configs/ppo_engine_tracking.toml: 64 envs,
64-step rollouts, 5 epochs of 2048-sample minibatches, a 64x64 MLP, VecNormalize) learns for a fixed
number of steps on each env's native vector env through ``make_sb3_vec_env``; the reference is the
same PPO on CartPole-v1 through SB3's own ``make_vec_env`` (64 gymnasium envs in a DummyVecEnv),
the path users know. Steps per second include the gradient updates. Best of ``--rounds``.
Prints and writes experiments/results/bench_ppo.md.

    python experiments/bench_ppo.py [--steps 262144] [--rounds 3]
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from agents.sb3 import check_config, load_config
from ssme_envs.envs.sb3_adapter import make_sb3_vec_env
from ssme_envs.outputs import write_text
from ssme_envs.script_options import int_within, script_parser

HERE = Path(__file__).resolve().parent
ENVS = ("ssme_envs/EngineTracking-v0", "ssme_envs/EngineThrottle-v0", "ssme_envs/NozzleTVC-v0")


def _steps_per_s(env_id: str, steps: int, config: dict) -> float:
    n = config["num_envs"]
    if env_id.startswith("ssme_envs/"):
        venv = VecMonitor(make_sb3_vec_env(env_id, n, seed=0))  # as make_vec_env's Monitors
    else:
        venv = make_vec_env(env_id, n_envs=n, seed=0)
    policy_kwargs = {"net_arch": config["policy"]["net_arch"]}
    model = PPO("MlpPolicy", VecNormalize(venv), seed=0, device="cpu", policy_kwargs=policy_kwargs,
                **config["hyperparameters"])  # fmt: skip
    start = time.perf_counter()
    model.learn(steps)
    return model.num_timesteps / (time.perf_counter() - start)


def main() -> None:
    parser = script_parser(__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int_within(1), default=262_144)
    parser.add_argument("--rounds", type=int_within(1), default=3)
    args = parser.parse_args()
    config = check_config(load_config(HERE / "configs" / "ppo_engine_tracking.toml"))
    rates: dict[str, float] = {}
    for _ in range(args.rounds):  # alternate the envs so that load drifts hit all of them alike
        for env_id in ("CartPole-v1", *ENVS):
            rates[env_id] = max(rates.get(env_id, 0.0), _steps_per_s(env_id, args.steps, config))
    reference = rates["CartPole-v1"]
    # the thread setting is part of the command: torch's thread count follows it
    threads = f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']} " if "OMP_NUM_THREADS" in os.environ else ""
    lines = [
        "# PPO throughput through the SB3 adapter",
        "",
        f"Command: `{threads}python experiments/bench_ppo.py --steps {args.steps} --rounds {args.rounds}` "
        f"(torch {torch.__version__}, {torch.get_num_threads()} threads). PPO steps per second including "
        "the updates, best of the rounds; the reference is the same PPO on CartPole-v1 through SB3's "
        "make_vec_env (DummyVecEnv), measured in the same run.",
        "",
        "| env | steps/s | x CartPole-v1 PPO |",
        "|---|---|---|",
        f"| CartPole-v1 (reference, DummyVecEnv) | {reference:,.0f} | 1.00 |",
    ]
    lines += [f"| {e} | {rates[e]:,.0f} | {rates[e] / reference:.2f} |" for e in ENVS]
    path = HERE / "results" / "bench_ppo.md"
    write_text(path, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
