"""``SkillChainingRunAgent``: the ``"skill-chaining"`` agent type, built from a run config.

``skillchain train --agent skill-chaining --runs 20 --episodes 250 --out DIR`` trains
:class:`~skillchain_torch.agents.SkillChainingAgent` agents with the paper's values (section
5.1) where the config keeps them: the top level as the flat agent (Sarsa, order 4 / alpha
0.001 on simple maps, order 5 / 0.0005 on hard maps, epsilon 0.01, gamma 1); options with an
order-3 Fourier Q-head (epsilon 0.01; ``config.option_alpha``), logistic initiation sets
(2nd-order features, eta = 0.1, 100 sweeps, the two classes weighted equally),
``config.gestation`` episodes of gestation (default 2; the paper: 10),
``config.convergence_threshold`` (0.15) twice, distance 0.1, branching 3, and
``config.slots`` option slots per agent. The goal is the only initial target event.
"""

from __future__ import annotations

import torch

from skillchain_torch.agents import SkillChainingAgent

from .config import TrainConfig

__all__ = ["SkillChainingRunAgent"]


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
        from skillchain_torch.options import OptionBank

        # Class-balanced initiation-set fits: see SkillChainingAgent.build.
        sizes = {} if cfg.env is None else dict(obs_dim=cfg.obs_dim, num_actions=cfg.num_actions)
        bank = OptionBank.build(cfg.runs, cfg.slots, seed=cfg.seed, device=device, balanced=True,
                                **sizes,
                                alpha=cfg.option_alpha,
                                initial_bias=cfg.initiation_bias,
                                keep_negatives=cfg.keep_negatives,
                                centered=cfg.initiation_centered)  # fmt: skip
        super().__init__(bank, order=cfg.order, alpha=cfg.alpha, gamma=cfg.gamma,
                         epsilon=cfg.epsilon, seed=cfg.seed,
                         scale_step_size=cfg.scale_step_size, device=device,
                         failure_bootstrap=cfg.failure_bootstrap, native=native,
                         intra_option_primitives=cfg.intra_option_primitives,
                         interruption=cfg.option_interruption,
                         reading=cfg.reading, policy_start=cfg.policy_start,
                         value_start=cfg.value_start, value_bonus=cfg.value_bonus,
                         completion_reward=cfg.completion_reward, gestation=cfg.gestation,
                         convergence_threshold=cfg.convergence_threshold)
        self.config = cfg
