"""rl-zoo3 PPO hyperparameters (``--conf-file ssme_envs.zoo.ppo``): those of the shipped PPO
policies (``experiments/configs/ppo_<env>.toml``; tests/test_zoo_entries.py holds them equal)."""

from ssme_envs.zoo import ENV_IDS

_PPO = {
    "policy": "MlpPolicy",
    "n_timesteps": 10_000_000,
    "n_envs": 64,
    "n_steps": 64,
    "batch_size": 2048,
    "n_epochs": 5,
    "learning_rate": 3e-4,
    "gamma": 0.98,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.0,
    "policy_kwargs": "dict(net_arch=[64, 64])",
}

# what an env's shipped policy was trained with beside _PPO
_OWN = {
    "ssme_envs/EngineThrottle-v0": {"n_timesteps": 16_000_000},
    # the unstable pole and the settling after a step span about 50 steps
    "ssme_envs/LauncherPitch-v0": {"n_timesteps": 15_000_000, "gamma": 0.99},
}


def _entry(env_id: str) -> dict:
    entry = {**_PPO, **_OWN.get(env_id, {})}
    # VecNormalize's reward scaling discounts with the algorithm's gamma, as `ssme-envs train` does
    entry["normalize"] = f"{{'norm_obs': True, 'norm_reward': True, 'gamma': {entry['gamma']}}}"
    return entry


hyperparams = {env_id: _entry(env_id) for env_id in ENV_IDS}
