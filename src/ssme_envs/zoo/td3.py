"""rl-zoo3 TD3 hyperparameters (``--conf-file ssme_envs.zoo.td3``); untuned starting points."""

from ssme_envs.zoo import ENV_IDS

_TD3 = {
    "policy": "MlpPolicy",
    "n_timesteps": 1_000_000,
    "normalize": "{'norm_obs': True, 'norm_reward': False}",
    "learning_rate": 1e-3,
    "buffer_size": 1_000_000,
    "batch_size": 256,
    "learning_starts": 10_000,
    "gamma": 0.98,
    "train_freq": 1,
    "gradient_steps": 1,
    "noise_type": "normal",
    "noise_std": 0.1,
    "policy_kwargs": "dict(net_arch=[256, 256])",
}

hyperparams = {env_id: dict(_TD3) for env_id in ENV_IDS}
