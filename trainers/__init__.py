"""Trainers: population training loops, their configs, hooks, checkpoints and the CLI.

Subpackages by role: :mod:`.loop` (the population trainer, the env steppers, a user's agent),
:mod:`.config` (the run config, its checks and fields, the agent registry, the CLI and its
arguments), :mod:`.outputs` (checkpoints, TensorBoard, the option monitor, the discovery log,
figures, progress), :mod:`.distributed` (blocks of agents, Ray) and :mod:`.study` (what reads
finished runs: reproduce, verify, the paper report).

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
    "AGENTS": "config.registry",
    "make_agent": "config.registry",
    "ActiveEnvStepper": "loop.population",
    "EnvStepper": "loop.env_stepper",
    "EpisodeBatch": "loop.population",
    "PopulationTrainer": "loop.population",
    "train_and_write": "outputs.run_outputs",
    "check_agent": "loop.user_agent",
    "STAGES": "loop.population",
    "FORMAT_VERSION": "outputs.checkpoint",
    "latest_checkpoint": "outputs.checkpoint",
    "load_checkpoint": "outputs.checkpoint",
    "read_checkpoint": "outputs.checkpoint",
    "save_checkpoint": "outputs.checkpoint",
    "TrainConfig": "config.config",
    "paper_defaults": "config.config",
    "TensorBoardHook": "outputs.logging",
    "ProgressBar": "outputs.progress",
    "plot_learning_curve": "outputs.plots",
    "save_learning_curve": "outputs.plots",
    "summarize": "study.summary",
    "load_run": "study.evaluate",
    "evaluate": "study.evaluate",
    "DiscoveryLog": "outputs.discovery_log",
    "option_tree": "outputs.discovery_log",
    "greedy_trajectory": "outputs.option_trajectory",
    "greedy_trajectories": "outputs.option_trajectory",
    "best_greedy_trajectory": "outputs.option_trajectory",
    "plot_option_trajectory": "outputs.option_trajectory",
    "SkillChainingRunAgent": "skillchain_torch.agents.skill_chaining_run",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = _EXPORTS[name]
    module = module if module.startswith("skillchain_torch.") else f"{__name__}.{module}"
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
