"""Random subgoals: the control that keeps skill chaining's machinery and drops its choice of
subgoals (issue 52's control (b)).

Skill chaining aims each new option at the initiation set of an option it already has, so the
chain grows backwards from the goal (section 4.3). The control aims the same number of options
at regions placed uniformly at random instead: :func:`random_subgoals` draws, for each agent,
``count`` discs in the ball's position whose centres are uniform over the map's free space, as
:class:`~skillchain_torch.options.RegionEvent` base events. Built with ``chaining=False``
(:class:`~.skill_chaining.SkillChaining`), the agent creates, gestates and fits options under
the same rules, but only the goal and these regions are ever targets: region n becomes a
target once the agent has n learned sets, at the moment chaining would have added its n-th
learned set as a target.

Agent ``p``'s centres are a pure function of ``seed + p`` (their own random stream), so agent p
alone draws the regions it draws in a population.

Example:
    >>> events = random_subgoals(population=2, count=3, seed=0, map="pinball_simple_single")
    >>> [e.name for e in events], tuple(events[0].center.shape)
    (['subgoal 1', 'subgoal 2', 'subgoal 3'], (2, 2))
    >>> alone = random_subgoals(population=1, count=3, seed=1, map="pinball_simple_single")
    >>> bool((alone[2].center[0] == events[2].center[1]).all())
    True
"""

from __future__ import annotations

import torch

from skillchain_torch.options import RegionEvent
from skillchain_torch.rng import CounterRNG

__all__ = ["SUBGOAL_RADIUS", "SUBGOALS", "random_subgoals"]

# The discs' radius: the paper's distance constraint (a learned set reaches 0.1 from a positive
# example), so a random subgoal is about as wide as a chained target near its examples. Not
# screened: it is the control's one free value.
SUBGOAL_RADIUS = 0.1
SUBGOALS = ("chained", "random")  # where new options aim: the paper's chain, or the control
_STREAM = 0x5_0B_60A1  # the subgoals' own stream: no number shared with the agent's others


def random_subgoals(population: int, count: int, seed: int | torch.Tensor,
                    map: str | None = None,
                    radius: float = SUBGOAL_RADIUS,
                    device: torch.device | str | None = None,
                    ) -> tuple[RegionEvent, ...]:  # fmt: skip
    """``count`` disc events per agent in the observation's first two dims (the ball's x, y),
    centred uniformly at random over the unit square outside the map's obstacles (``map``
    ``None``: the whole square). ``seed``: agent p's is ``seed + p``, or a ``[P]`` tensor of
    the agents' seeds."""
    if count < 0 or radius <= 0:
        raise ValueError(f"random subgoals need count >= 0 and radius > 0, got {count}, {radius}")
    obstacles = _obstacles(map)
    if isinstance(seed, torch.Tensor):
        seeds = seed.to("cpu", torch.int64).reshape(-1)
        if seeds.numel() != population:
            raise ValueError(f"need {population} seeds, got {seeds.numel()}")
    else:
        seeds = CounterRNG.from_seed(int(seed), population).seeds
    centers = torch.empty(population, count, 2, dtype=torch.float64)
    for p in range(population):  # rejection, row by row: agent p's draws are its own
        agent = CounterRNG(seeds[p:p + 1], stream=_STREAM)
        found = 0
        while found < count:
            x, y = agent.uniform(2)[0].tolist()
            if not any(inside(x, y) for inside in obstacles):
                centers[p, found] = torch.tensor([x, y], dtype=torch.float64)
                found += 1
    return tuple(RegionEvent(centers[:, i].to(device), radius, name=f"subgoal {i + 1}")
                 for i in range(count))  # fmt: skip


def _obstacles(map: str | None) -> list:
    """Point-in-obstacle tests of the map's polygons (none off Pinball)."""
    if map is None:
        return []
    from skillchain_torch.envs.pinball.geometry import point_in_polygon  # the env's own
    from skillchain_torch.envs.pinball.maps import load_map

    polygons = [poly.tolist() for poly in load_map(map).polygons]
    return [lambda x, y, poly=poly: point_in_polygon(x, y, poly) for poly in polygons]
