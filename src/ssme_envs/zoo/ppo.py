"""rl-zoo3 PPO hyperparameters (``--conf-file ssme_envs.zoo.ppo``)."""

from ssme_envs.zoo import ENV_IDS

_PPO = {
    "policy": "MlpPolicy",
    "n_timesteps": 10_000_000,
    "n_envs": 64,
    "normalize": "{'norm_obs': True, 'norm_reward': True, 'gamma': 0.98}",
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

hyperparams = {env_id: dict(_PPO) for env_id in ENV_IDS}
