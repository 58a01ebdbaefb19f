"""The two CartPole workloads measured against PureJaxRL, in both projects' terms: PureJaxRL's
own CartPole settings (its `ppo.py`) and the paper's protocol, neither normalising
observations or rewards, on gymnax CartPole-v1 (500-step episodes)."""

from typing import Any

from gymnax.environments.classic_control import CartPole

from fppo_jax import TrainConfig, hyperparameters
from fppo_jax.core.config import Hyperparameters
from fppo_jax.envs import GymnaxEnvironment

WORKLOADS: dict[str, dict[str, Any]] = {
    "purejaxrl": {
        "title": "PureJaxRL's CartPole settings (4 envs × 128, 4 minibatches × 4 epochs)",
        "shape": {"num_envs": 4, "num_steps": 128, "num_minibatches": 4, "num_epochs": 4},
        "lr": 2.5e-4,
        "anneal": True,
        "entropy": 0.01,
    },
    "paper": {
        "title": "the paper's protocol (8 envs × 256, 32 minibatches × 10 epochs)",
        "shape": {"num_envs": 8, "num_steps": 256, "num_minibatches": 32, "num_epochs": 10},
        "lr": 3e-4,
        "anneal": False,
        "entropy": 0.0,
    },
}


def fppo(
    workload: str, total_steps: int = 500_000
) -> tuple[GymnaxEnvironment, TrainConfig, Hyperparameters]:
    """`workload` as fppo-jax runs it: the environment, the static config, PPO's settings."""
    spec = WORKLOADS[workload]
    cartpole = CartPole()
    config = TrainConfig(
        total_steps=total_steps,
        **spec["shape"],
        hidden_sizes=(64, 64),
        normalize_observations=False,
        normalize_rewards=False,
        clip_value_loss=True,
        anneal_learning_rate=spec["anneal"],
    )
    hp = hyperparameters(
        "ppo", learning_rate=spec["lr"], entropy_coef=spec["entropy"], max_grad_norm=0.5
    )
    return GymnaxEnvironment(cartpole, cartpole.default_params), config, hp


def purejaxrl(workload: str, total_steps: int) -> dict[str, Any]:
    """`workload` as PureJaxRL's `ppo.make_train` takes it."""
    spec, shape = WORKLOADS[workload], WORKLOADS[workload]["shape"]
    return {
        "LR": spec["lr"],
        "NUM_ENVS": shape["num_envs"],
        "NUM_STEPS": shape["num_steps"],
        "TOTAL_TIMESTEPS": total_steps,
        "UPDATE_EPOCHS": shape["num_epochs"],
        "NUM_MINIBATCHES": shape["num_minibatches"],
        "GAMMA": 0.99,
        "GAE_LAMBDA": 0.95,
        "CLIP_EPS": 0.2,
        "ENT_COEF": spec["entropy"],
        "VF_COEF": 0.5,
        "MAX_GRAD_NORM": 0.5,
        "ACTIVATION": "tanh",
        "ENV_NAME": "CartPole-v1",
        "ANNEAL_LR": spec["anneal"],
        "DEBUG": False,
    }
