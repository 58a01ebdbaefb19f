"""PureJaxRL's CartPole PPO settings (its `ppo.py`), expressed in fppo-jax terms."""

from gymnax.environments.classic_control import CartPole

from fppo_jax import TrainConfig, hyperparameters
from fppo_jax.envs import GymnaxEnvironment


def env() -> GymnaxEnvironment:
    """CartPole-v1 (500-step episodes), as PureJaxRL trains it."""
    cartpole = CartPole()
    return GymnaxEnvironment(cartpole, cartpole.default_params)


def config(total_steps: int = 500_000) -> TrainConfig:
    """4 envs × 128 steps, 4 epochs × 4 minibatches, 64×64 tanh, lr annealed, no normalisation."""
    return TrainConfig(
        total_steps=total_steps,
        num_envs=4,
        num_steps=128,
        num_minibatches=4,
        num_epochs=4,
        hidden_sizes=(64, 64),
        normalize_observations=False,
        normalize_rewards=False,
        clip_value_loss=True,
        anneal_learning_rate=True,
    )


def hp():
    return hyperparameters("ppo", learning_rate=2.5e-4, entropy_coef=0.01, max_grad_norm=0.5)
