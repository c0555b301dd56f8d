"""Trainers: population training loops, their configs, hooks, checkpoints and the CLI.

Names are imported lazily, so ``skillchain --help`` does not pay for importing torch.

Example:
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(runs=3, episodes=2, max_episode_steps=50))
    >>> trainer.train().returns.shape
    (3, 2)
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "AGENTS": "agents",
    "make_agent": "agents",
    "ActiveEnvStepper": "population",
    "EnvStepper": "env_stepper",
    "EpisodeBatch": "population",
    "PopulationTrainer": "population",
    "train_and_write": "run_outputs",
    "check_agent": "user_agent",
    "STAGES": "population",
    "FORMAT_VERSION": "checkpoint",
    "latest_checkpoint": "checkpoint",
    "load_checkpoint": "checkpoint",
    "read_checkpoint": "checkpoint",
    "save_checkpoint": "checkpoint",
    "TrainConfig": "config",
    "paper_defaults": "config",
    "TensorBoardHook": "logging",
    "ProgressBar": "progress",
    "plot_learning_curve": "plots",
    "save_learning_curve": "plots",
    "summarize": "study.summary",
    "DiscoveryLog": "discovery_log",
    "option_tree": "discovery_log",
    "greedy_trajectory": "option_trajectory",
    "greedy_trajectories": "option_trajectory",
    "best_greedy_trajectory": "option_trajectory",
    "plot_option_trajectory": "option_trajectory",
    "SkillChainingRunAgent": "skill_chaining",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
