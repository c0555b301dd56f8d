"""A hand-built option, "reach the region around the target", to demonstrate given options.

:func:`make_region_option` builds a one-agent :class:`~skillchain_torch.options.OptionBank`
whose slot 0 holds a LEARNED option on a Pinball map:

* **termination**: the goal event (target event 0, :class:`~skillchain_torch.options.GoalEvent`,
  the default event list of :class:`~skillchain_torch.agents.HierarchicalAgent`), so the bank
  file needs no extra description of its target;
* **initiation set**: the logistic classifier fitted on positions sampled within ``radius`` of
  the target (any velocity, labelled positive) and elsewhere on the board (negative), then
  constrained to lie within ``constraint`` (in x, y) of a positive example;
* **policy**: the option's Fourier Q-head pre-trained by intra-option Q-learning on random-action
  experience from free positions inside the region (balls restarted when they reach the goal,
  leave the region, or after ``horizon`` steps). This is a brief demonstration: with the
  defaults (140,000 transitions, about 5 s) its greedy policy reaches the goal within 250 steps
  from roughly 65-80% of the region's free positions depending on the seed, about as often as
  random actions do; the option keeps learning intra-option inside the agent. (Larger
  pre-training step sizes, ``>= 0.01`` with 256 features, are unstable.)

Run as a script to write the file used by ``skillchain train --agent given-options``::

    python -m skillchain_torch.agents.region_option region_option.pt

Example:
    >>> bank = make_region_option(examples=200, pretrain_steps=20, batch=20)
    >>> bank.status.tolist(), bank.target_event.tolist()
    ([[3]], [[0]])
"""

from __future__ import annotations

import argparse
import math

import torch
from torch import Tensor

from skillchain_torch.envs.pinball import NUM_ACTIONS, load_map, observation, pinball_step
from skillchain_torch.objectives import IntraOptionQLearning
from skillchain_torch.options import (
    FourierOptionQHead,
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
)

__all__ = ["make_region_option", "inside_obstacle", "main"]


def inside_obstacle(points: Tensor, pinball_map) -> Tensor:
    """``[N]`` bool: the ``[N, 2]`` positions inside any obstacle polygon (even-odd ray cast)."""
    inside = torch.zeros(points.shape[0], dtype=torch.bool)
    x, y = points[:, 0:1], points[:, 1:2]
    for poly in pinball_map.polygons:
        poly = poly.to(points.dtype).cpu()
        a, b = poly, torch.roll(poly, -1, dims=0)
        straddles = (a[:, 1] > y) != (b[:, 1] > y)  # [N, E]
        t = (y - a[:, 1]) / torch.where(b[:, 1] == a[:, 1], torch.ones(()), b[:, 1] - a[:, 1])
        cross = x < a[:, 0] + t * (b[:, 0] - a[:, 0])
        inside ^= ((straddles & cross).sum(-1) % 2) == 1
    return inside


def _free_positions(n: int, center: Tensor, radius: float, pinball_map,
                    gen: torch.Generator) -> Tensor:
    """``n`` positions uniform in the disc ``(center, radius)``, a ball radius inside the board
    and off the obstacles (rejection sampling)."""
    out = []
    margin = pinball_map.ball_radius
    while sum(p.shape[0] for p in out) < n:
        r = radius * torch.sqrt(torch.rand(4 * n, generator=gen, dtype=torch.float64))
        theta = 2 * math.pi * torch.rand(4 * n, generator=gen, dtype=torch.float64)
        pts = center + torch.stack([r * torch.cos(theta), r * torch.sin(theta)], -1)
        ok = ((pts > margin) & (pts < 1 - margin)).all(-1) & ~inside_obstacle(pts, pinball_map)
        out.append(pts[ok])
    return torch.cat(out)[:n]


@torch.no_grad()
def make_region_option(
    map_name: str = "pinball_simple_single",
    radius: float = 0.25,
    slots: int = 1,
    order: int = 3,
    alpha: float = 0.0005,
    examples: int = 500,
    fit_rounds: int = 20,
    constraint: float = 0.1,
    pretrain_steps: int = 700,
    batch: int = 200,
    pretrain_alpha: float = 0.002,
    horizon: int = 100,
    completion_reward: float = 10_000.0,
    seed: int = 0,
) -> OptionBank:
    """An :class:`OptionBank` (P = 1, ``slots`` slots) whose slot 0 reaches the target.

    Args:
        map_name: the Pinball map (its target centre defines the region).
        radius: positions within this distance of the target (x, y) are positive examples.
        slots: K of the bank (slot 0 holds the option, the others stay EMPTY).
        order, alpha: the option's Fourier Q-head (paper: 3, 0.0005).
        examples: labelled examples for the classifier (half positive, half negative).
        fit_rounds: classifier fits of ``sweeps`` (100) gradient steps each.
        constraint: membership also requires an (x, y) distance below this to a positive.
        pretrain_steps: minibatch intra-option Q-learning steps of the pre-training.
        batch: balls simulated side by side (transitions per minibatch).
        pretrain_alpha: the pre-training step size (the saved head keeps ``alpha``).
        horizon: a pre-training ball restarts after this many steps (or at the goal, or
            ``radius + 0.05`` away from the target).
        completion_reward: ``C`` used in the pre-training (as the agent's default).
        seed: of the sampling and of the bank's random streams.
    """
    gen = torch.Generator().manual_seed(seed)
    pinball_map = load_map(map_name)
    center = torch.tensor(pinball_map.target, dtype=torch.float64)
    classifier = InitiationClassifier(1, slots, capacity=examples, distance=constraint,
                                      distance_dims=(0, 1), seed=seed)
    bank = OptionBank(1, slots, FourierOptionQHead(1, slots, order=order, alpha=alpha),
                      classifier)
    # ---- initiation set: positives in the disc, negatives on the rest of the board.
    half = examples // 2
    pos_xy = _free_positions(half, center, radius, pinball_map, gen)
    neg_xy = torch.rand(4 * examples, 2, generator=gen, dtype=torch.float64)
    far = torch.linalg.vector_norm(neg_xy - center, dim=-1) > radius
    neg_xy = neg_xy[far][: examples - half]
    xy = torch.cat([pos_xy, neg_xy])
    vel = torch.rand(xy.shape[0], 2, generator=gen, dtype=torch.float64)
    obs = torch.cat([xy, vel], -1)
    labels = torch.arange(xy.shape[0]) < half
    classifier.add_examples(0, 0, obs, labels)
    slot0 = torch.zeros(1, slots, dtype=torch.bool)
    slot0[0, 0] = True
    for _ in range(fit_rounds):
        classifier.fit(slot0)
    classifier.constrain(slot0)
    bank.status[0, 0] = int(OptionStatus.LEARNED)
    bank.target_event[0, 0] = 0  # GoalEvent
    bank.created_episode[0, 0] = 0
    # ---- policy: intra-option Q-learning on random experience from the region, as minibatch
    # TD: ``batch`` copies of the head each take one transition, then are averaged (the mean of
    # their steps), which is ``batch`` times faster than one transition per update.
    head = bank.q_head.select_agents([0] * batch)
    head.alpha = pretrain_alpha
    update = IntraOptionQLearning(1.0, completion_reward)
    goal = GoalEvent()
    everyone = torch.ones(batch, 1, dtype=torch.bool)

    def fresh(n: int) -> Tensor:
        return torch.cat([_free_positions(n, center, radius, pinball_map, gen),
                          torch.zeros(n, 2, dtype=torch.float64)], -1)

    state = fresh(batch)
    age = torch.zeros(batch, dtype=torch.int64)
    for _ in range(pretrain_steps):
        action = torch.randint(0, NUM_ACTIONS, (batch,), generator=gen)
        nxt, reward, terminated = pinball_step(state, action, pinball_map)
        o1 = observation(nxt)
        update(head, observation(state), action, reward, o1, terminated, everyone,
               goal(o1, terminated)[:, None])
        head.weight.copy_(head.weight.mean(0, keepdim=True).expand_as(head.weight))
        age += 1
        left = torch.linalg.vector_norm(nxt[:, :2] - center, dim=-1) > radius + 0.05
        restart = terminated | left | (age >= horizon)
        if bool(restart.any()):
            nxt = nxt.clone()
            nxt[restart] = fresh(int(restart.sum()))
            age[restart] = 0
        state = nxt
    bank.q_head.weight.copy_(head.weight[:1])
    return bank


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write the hand-built region option bank.")
    parser.add_argument("out", help="output file (OptionBank.save format)")
    parser.add_argument("--map", default="pinball_simple_single")
    parser.add_argument("--slots", type=int, default=1)
    parser.add_argument("--pretrain-steps", type=int, default=700)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    bank = make_region_option(args.map, slots=args.slots, pretrain_steps=args.pretrain_steps,
                              seed=args.seed)
    bank.save(args.out)
    print(f"wrote {args.out}: {bank.slots} slot(s), slot 0 reaches the target of {args.map}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
