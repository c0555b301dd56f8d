"""``GivenOptionsAgent``: the ``"given-options"`` agent type, options loaded from a file.

``skillchain train --agent given-options --options PATH ...`` starts every agent of the
population with agent 0's options (``--options-agent N``: agent N's; ``each``: agent p gets
saved agent p's) of the :class:`~skillchain_torch.options.OptionBank` file at
``PATH`` (written by ``OptionBank.save``, e.g. by ``python -m
skillchain_torch.agents.region_option PATH``). The options keep learning their Q-heads by
intra-option Q-learning; their initiation sets are used as given (no discovery), and every live
slot is made LEARNED (executable). The top level is SMDP Sarsa with the run's ``order``,
``alpha``, ``gamma`` and ``epsilon`` (paper values by default).

The file's path is read from ``config.options`` (the ``--options`` flag). Options from a
skill-chaining run (``DIR/options.pt``) keep the no-overlap rule they were learned under.
"""

from __future__ import annotations

import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.options import OptionBank, OptionStatus

from .config import TrainConfig

__all__ = ["GivenOptionsAgent", "load_given_options"]


def load_given_options(path, population: int, seed: int = 0,
                       device: torch.device | str | None = None,
                       agent: int | None = 0) -> OptionBank:  # fmt: skip
    """Saved agent ``agent``'s options from ``path`` replicated ``population`` times (or, with
    ``agent=None``, saved agent ``p mod N`` for agent p), reseeded ``seed + p``.

    Options that were executable (LEARNING or LEARNED) become LEARNED; gestating ones, never
    executed and with no initiation set yet, are dropped (their slots emptied)."""
    seeds = torch.arange(population, dtype=torch.int64) + int(seed)
    saved = OptionBank.load(path, device=device)
    if agent is not None and not 0 <= agent < saved.population:
        raise ValueError(f"{path} holds agents 0..{saved.population - 1}; options_agent "
                         f"{agent} is not one of them")  # fmt: skip
    index = [agent] * population if agent is not None else [
        p % saved.population for p in range(population)]
    bank = saved.select_agents(index, seeds)
    bank.free(bank.status == OptionStatus.GESTATING)
    bank.set_status(bank.live(), OptionStatus.LEARNED)
    return bank


class GivenOptionsAgent(HierarchicalAgent):
    """:class:`HierarchicalAgent` built from a :class:`TrainConfig` and an options file.

    Args:
        config: the run; ``config.options`` is the OptionBank file (required).
        device: torch device (default ``config.device``).
    """

    def __init__(self, config: TrainConfig, device: torch.device | str | None = None,
                 native: bool | None = None):
        cfg = config.resolved()
        path = getattr(cfg, "options", None)
        if not path:
            raise ValueError("the given-options agent needs an options file (--options PATH)")
        device = torch.device(cfg.device if device is None else device)
        bank = load_given_options(path, cfg.runs, cfg.seed, device=device,
                                  agent=cfg.options_agent)
        super().__init__(bank, order=cfg.order, alpha=cfg.alpha, gamma=cfg.gamma,
                         epsilon=cfg.epsilon, seed=cfg.seed,
                         scale_step_size=cfg.scale_step_size, device=device,
                         failure_bootstrap=cfg.failure_bootstrap,
                         overlap=True,  # as the options were learned (no-op if unrelated)
                         completion_reward=cfg.completion_reward, native=native)
        self.config = cfg
