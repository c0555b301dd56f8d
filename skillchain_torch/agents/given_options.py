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
A bank learned on another map, or for another observation size or action count, is refused
(``ValueError`` naming the field); banks saved before they recorded their map load with a
warning that the map cannot be checked.
"""

from __future__ import annotations

import logging

import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.agents.hierarchical import OBS_DIM
from skillchain_torch.envs.pinball import NUM_ACTIONS
from skillchain_torch.options import OptionBank, OptionStatus
from skillchain_torch.options.goals import env_goal, goal_event
from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["GivenOptionsAgent", "load_given_options"]

logger = logging.getLogger(__name__)


def load_given_options(path, population: int, seed: int = 0,
                       device: torch.device | str | None = None,
                       agent: int | None = 0, map: str | None = None,
                       obs_dim: int | None = None,
                       num_actions: int | None = None) -> OptionBank:  # fmt: skip
    """Saved agent ``agent``'s options from ``path`` replicated ``population`` times (or, with
    ``agent=None``, saved agent ``p mod N`` for agent p), reseeded ``seed + p``.

    Options that were executable (LEARNING or LEARNED) become LEARNED; gestating ones, never
    executed and with no initiation set yet, are dropped (their slots emptied; a warning is
    logged when that leaves an agent without options; another when all of a saved agent's
    initiation sets are empty on Pinball's probe grid). ``map``: the run's map; a bank that
    records another one is refused (``ValueError``), as is one for another observation size
    or action count than Pinball's, or an ``agent`` the file does not hold."""
    seeds = torch.arange(population, dtype=torch.int64) + int(seed)
    saved = OptionBank.load(path, device=device)
    saved.check_environment(path, map=map, obs_dim=obs_dim or OBS_DIM,
                            num_actions=num_actions or NUM_ACTIONS)  # fmt: skip
    if saved.legacy and map is not None:
        logger.warning("%s records no map (saved before option banks did): cannot check that "
                       "its options were learned on %s", path, map)
    if agent is not None and not 0 <= agent < saved.population:
        raise ValueError(f"--options-agent {agent}: {path} holds {saved.population} agent"
                         f"{'s' if saved.population != 1 else ''}, so expected 0.."
                         f"{saved.population - 1} or 'each'")  # fmt: skip
    if agent is None and population > saved.population:
        logger.warning("%s holds %d agents and this run has %d: with --options-agent each, "
                       "agent p takes saved agent p mod %d's options (agents share them)",
                       path, saved.population, population, saved.population)
    index = [agent] * population if agent is not None else [
        p % saved.population for p in range(population)]
    bank = saved.select_agents(index, seeds)
    bank.free(bank.status == OptionStatus.GESTATING)
    bank.set_status(bank.live(), OptionStatus.LEARNED)
    _warn_empty(path, saved, index)
    if saved.obs_dim == OBS_DIM:  # the probe grid is Pinball's
        _warn_dead(path, saved, index)
    return bank


def _warn_dead(path, saved: OptionBank, index: list[int]) -> None:
    """Log the saved agents whose executable options all have empty initiation sets (on the
    Figure-5 probe grid): the agents given them can never take an option. The paper preset's
    hard-instance banks are all of this kind (sets true everywhere, refitted on timeouts)."""
    from skillchain_torch.trainers.study.option_census import dead_agents

    executable = saved.executable().any(-1).tolist()
    dead = dead_agents(saved, sorted({a for a in index if executable[a]}))
    if dead:
        users = sum(index.count(a) for a in dead)
        named = str(dead) if len(dead) <= 8 else \
            f"[{', '.join(map(str, dead[:8]))}, ...] ({len(dead)} in all)"
        logger.warning("%s: no option of saved agent(s) %s holds a state of the Figure-5 probe "
                       "grid (every initiation set is empty); %d of this run's %d agents will "
                       "likely never take an option and learn as flat agents",
                       path, named, users, len(index))  # fmt: skip


def _warn_empty(path, saved: OptionBank, index: list[int]) -> None:
    """Log the saved agents whose options are all dropped or absent, so that the agents
    given them start with 0 options."""
    executable = saved.executable().any(-1).tolist()
    gestating = (saved.status == OptionStatus.GESTATING).sum(-1).tolist()
    without = sorted({a for a in index if not executable[a]})
    for kind, agents in (("gestating", [a for a in without if gestating[a]]),
                         ("none", [a for a in without if not gestating[a]])):  # fmt: skip
        if not agents:
            continue
        users = sum(index.count(a) for a in agents)
        start = f"{users} of this run's {len(index)} agents start with 0 options"
        if kind == "gestating":
            n = sum(gestating[a] for a in agents)
            logger.warning("%s: the options of saved agent(s) %s are all still gestating: %d "
                           "option(s) dropped (never executed, no initiation set yet); %s",
                           path, agents, n, start)
        else:
            logger.warning("%s: saved agent(s) %s hold no options; %s", path, agents, start)


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
                                  agent=cfg.options_agent, map=cfg.env_name,
                                  obs_dim=cfg.obs_dim, num_actions=cfg.num_actions)
        super().__init__(bank, order=cfg.order, alpha=cfg.alpha, gamma=cfg.gamma,
                         epsilon=cfg.epsilon, seed=cfg.seed,
                         scale_step_size=cfg.scale_step_size, device=device,
                         failure_bootstrap=cfg.failure_bootstrap,
                         intra_option_primitives=cfg.intra_option_primitives,
                         intra_option_target=cfg.intra_option_target,
                         interruption=cfg.option_interruption,
                         end_outside_set=cfg.end_outside_set,
                         max_option_steps=cfg.max_option_steps,
                         overlap=True,  # as the options were learned (no-op if unrelated)
                         completion_reward=cfg.completion_reward, native=native,
                         events=(goal_event(cfg.goal or env_goal(cfg.env)),))  # (None: terminated)
        self.config = cfg
