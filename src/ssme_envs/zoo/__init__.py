"""Hyperparameters for rl-zoo3, one module per algorithm.

rl-zoo3 reads a module's ``hyperparams`` dict (keyed by env id) when given its import path::

    pip install "ssme-envs[zoo]"
    python -m rl_zoo3.train --algo ppo --env ssme_envs/EngineTracking-v0 \\
        --gym-packages ssme_envs --conf-file ssme_envs.zoo.ppo

The PPO entries are the settings of the shipped PPO policies (experiments/configs/ppo_<env>.toml),
with the zoo's vectorization (scalar envs in a DummyVecEnv; ``ssme-envs train`` steps the native
vector env and is several times faster). The SAC and TD3 entries are untuned starting points.
"""

from ssme_envs.envs.catalogue import ENVS

ENV_IDS = tuple(ENVS)
