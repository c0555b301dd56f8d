"""``SkillChainingRunAgent``: the ``"skill-chaining"`` agent type, built from a run config.

``skillchain train --agent skill-chaining --runs 20 --episodes 250 --out DIR`` trains
:class:`~skillchain_torch.agents.SkillChainingAgent` agents built as
``SkillChainingAgent.build(preset=config.preset)`` builds them, with the config's values over
the preset's (``--preset paper``: section 5.1's; see :mod:`skillchain_torch.presets`): the top
level as the flat agent (Sarsa, order 4 / alpha 0.001 on simple maps, order 5 / 0.0005 on hard
maps, epsilon 0.01, gamma 1); options with an order-3 Fourier Q-head (epsilon 0.01;
``config.option_alpha``), logistic initiation sets (2nd-order features, eta = 0.1, 100 sweeps,
the two classes weighted equally), ``config.gestation`` episodes of gestation,
``config.convergence_threshold`` twice, distance 0.1, branching 3, and ``config.slots`` option
slots per agent. The goal (``config.goal``, else the env's: :mod:`skillchain_torch.options.goals`)
is the only initial target event.
"""

from __future__ import annotations

import logging

import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.options.goals import env_goal, goal_event, goal_note
from skillchain_torch.trainers.config.config import PRESET_CONFIG_FIELDS, TrainConfig

__all__ = ["SkillChainingRunAgent"]

logger = logging.getLogger("skillchain_torch.agents")


class SkillChainingRunAgent(SkillChainingAgent):
    """:class:`SkillChainingAgent` built from a :class:`TrainConfig` (``config.slots`` slots).

    Example:
        >>> agent = SkillChainingRunAgent(TrainConfig(agent="skill-chaining", runs=2, slots=3))
        >>> agent.bank.slots, agent.num_decisions
        (3, 8)
    """

    def __init__(self, config: TrainConfig, device: torch.device | str | None = None,
                 native: bool | None = None):
        cfg = config.resolved()
        device = torch.device(cfg.device if device is None else device)
        # The config's values over its preset's, built as SkillChainingAgent.build builds: so
        # build(preset=...) and the trainer's agent of the same values are the same agent.
        values = {name: getattr(cfg, name) for name in PRESET_CONFIG_FIELDS}
        learner = (dict(lr=cfg.top_lr, target_update=cfg.top_target_update,
                        bootstrap=cfg.top_bootstrap) if cfg.top_head == "mlp" else None)
        note = goal_note(cfg.env)  # an env the library does not know: say what its goal is
        if note:
            logger.warning(note)
        goal = goal_event(cfg.goal or env_goal(cfg.env))
        bank, arguments = SkillChainingAgent.build_arguments(
            cfg.runs, cfg.preset, seed=cfg.seed, device=device, map=cfg.map, native=native,
            obs_dim=cfg.obs_dim, num_actions=cfg.num_actions, top_head=cfg.top_head,
            option_head=cfg.option_head, initiation=cfg.initiation, top_learner=learner,
            goal=goal, **values)  # fmt: skip
        super().__init__(bank, **arguments)
        self.config = cfg
