"""rl-zoo3 SAC hyperparameters (``--conf-file ssme_envs.zoo.sac``); untuned starting points."""

from ssme_envs.zoo import ENV_IDS

_SAC = {
    "policy": "MlpPolicy",
    "n_timesteps": 1_000_000,
    "normalize": "{'norm_obs': True, 'norm_reward': False}",
    "learning_rate": 3e-4,
    "buffer_size": 1_000_000,
    "batch_size": 256,
    "learning_starts": 10_000,
    "gamma": 0.98,
    "tau": 0.005,
    "train_freq": 1,
    "gradient_steps": 1,
    "policy_kwargs": "dict(net_arch=[256, 256])",
}

hyperparams = {env_id: dict(_SAC) for env_id in ENV_IDS}
