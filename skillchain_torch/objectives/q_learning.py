"""Intra-option Q-learning for every option slot (paper section 5.1: ``gamma = 1``).

Every primitive transition ``(s, a, r, s')``, whoever chose ``a`` (the top level, another option,
or the option itself), updates the options :func:`option_update_mask` names:

* **on-policy**: the executing option, wherever ``s`` is. Section 5.1 ignores "off-policy
  updates to an option for states outside its initiation set"; an execution's own steps are
  on-policy, and one that strays out of its set (or its 0.1 tube) must still learn there, or
  its in-set targets bootstrap from values nothing trains;
* **off-policy**: every other option whose own initiation set (the classifier's) holds ``s``.
  The no-overlap rule of section 4.3 narrows sets for *choosing* an option only: a younger
  sibling still learns inside its elder's region, which it may cross on its way to their
  common target.

Each updated option ``k`` moves toward

    target_k = r + C * T_k(s') + gamma * max_a' Q_k(s', a') * (1 - (T_k(s') or terminated))
    delta_k  = target_k - Q_k(s, a)

where ``T_k`` is option k's termination predicate (its target event) and ``C`` the completion
reward. The option's reward function is the task's reward plus ``C`` for triggering its target
(section 4.1); an option stops at its target, so it does not bootstrap there.

Example:
    >>> import torch
    >>> from skillchain_torch.options import FourierOptionQHead
    >>> head = FourierOptionQHead(population=1, slots=2, order=1, alpha=0.0)
    >>> obs = torch.zeros(1, 4, dtype=torch.float64)
    >>> update = IntraOptionQLearning(gamma=1.0, completion_reward=100.0)
    >>> update(head, obs, action=torch.tensor([4]), reward=torch.tensor([-1.0]), next_obs=obs,
    ...        env_terminated=torch.tensor([False]),
    ...        in_initiation=torch.tensor([[True, False]]),
    ...        target_reached=torch.tensor([[True, True]])).tolist()
    [[99.0, 0.0]]
    >>> option_update_mask(torch.tensor([[True, False, False]]), torch.tensor([2])).tolist()
    [[True, False, True]]
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from skillchain_torch.options.q_head import OptionQHead
from skillchain_torch.options.status import check_slot_mask

__all__ = ["IntraOptionQLearning", "option_td_target", "option_update_mask"]


def option_update_mask(in_initiation: Tensor, executing: Tensor | None = None,
                       learnable: Tensor | None = None) -> Tensor:
    """``BoolTensor [P, K]``: the option slots a transition from ``s`` updates (module docstring).

    Args:
        in_initiation: ``[P, K]`` ``s`` lies in option k's own initiation set (the classifier's,
            not narrowed by the no-overlap rule): off-policy updates.
        executing: ``LongTensor [P]`` the slot that chose the action at ``s``, ``-1`` for
            none: its on-policy update, wherever ``s`` is. ``None``: no option executing.
        learnable: ``[P, K]`` slots that may learn at all (live, and stepped), default all.
    """
    mask = in_initiation
    if executing is not None:
        slots = torch.arange(mask.shape[1], device=mask.device)
        mask = mask | (slots[None, :] == executing.reshape(-1, 1).to(mask.device))
    return mask if learnable is None else mask & learnable


def option_td_target(
    reward: Tensor,
    next_q_max: Tensor,
    target_reached: Tensor,
    env_terminated: Tensor,
    gamma: float = 1.0,
    completion_reward: float | Tensor = 10_000.0,
) -> Tensor:
    """``r + C * T + gamma * max_a Q(s', a) * (1 - (T | terminated))``, all ``[P, K]``.

    Args:
        reward: ``[P]`` (or ``[P, 1]``) the primitive reward of the transition.
        next_q_max: ``[P, K]`` ``max_a Q_k(s', a)``; ignored (may be inf) where not bootstrapped.
        target_reached: ``BoolTensor [P, K]``, each option's termination predicate at ``s'``.
        env_terminated: ``BoolTensor [P]`` (or ``[P, 1]``), the episode ended at ``s'``.
        completion_reward: a float, or a tensor broadcastable to ``[P, K]`` (per slot).
    """
    population = next_q_max.shape[0]
    reached = target_reached.to(torch.bool)
    stop = reached | env_terminated.reshape(population, 1).to(torch.bool)
    bootstrap = torch.where(stop, torch.zeros_like(next_q_max), gamma * next_q_max)
    completion = torch.as_tensor(completion_reward, dtype=next_q_max.dtype,
                                 device=next_q_max.device)  # fmt: skip
    bonus = torch.where(reached, completion, torch.zeros_like(completion))
    r = reward.reshape(population, 1).to(next_q_max.dtype)
    return (r + bonus) + bootstrap


class IntraOptionQLearning(nn.Module):
    """Off-policy Q-learning step for all option slots of all agents at once.

    Args:
        gamma: discount (paper: 1).
        completion_reward: ``C``, added to the reward when an option's target event fires at
            ``s'``; a float or a ``[P, K]``-broadcastable tensor. Default ``10_000``.

    Why ``C = 10_000``: the paper gives no value. Pinball's per-step rewards are -1 / -5 and an
    option's trajectory lasts at most 250 steps (at most -1250), so ``C`` must dominate that for
    an option's values to point at its target, and a value of the order of the goal reward
    (10,000) gives every option in a chain the same scale of value at its target as the goal
    option has at the goal. An option whose target is the goal (``GoalEvent``) receives the
    environment's +10,000 *and* ``C`` when it reaches the goal (``r + C = 20,000``): this is the
    paper's definition taken literally ("R plus an option completion reward") and only shifts
    that option's values by a constant at its target, which cannot change its greedy policy.
    Pass a per-slot tensor (e.g. ``C = 0`` for goal-targeting slots) for the other convention.

    The caller chooses which slots learn (``learnable``, e.g. ``bank.live()``) and drops the
    transitions of unsuccessful on-policy executions (paper 5.1) by excluding those slots.
    Everything is elementwise or a max over 5 actions, so with :class:`FourierOptionQHead`
    agent p's update is bit-identical alone or in a population.
    """

    def __init__(self, gamma: float = 1.0, completion_reward: float | Tensor = 10_000.0):
        super().__init__()
        self.gamma = float(gamma)
        self.completion_reward = completion_reward

    @torch.no_grad()
    def forward(
        self,
        q_head: OptionQHead,
        obs: Tensor,
        action: Tensor,
        reward: Tensor,
        next_obs: Tensor,
        env_terminated: Tensor,
        in_initiation: Tensor,
        target_reached: Tensor,
        learnable: Tensor | None = None,
        code: Tensor | None = None,
        next_code: Tensor | None = None,
        executing: Tensor | None = None,
        stepped: Tensor | None = None,
    ) -> Tensor:
        """Update the ``(p, k)`` of :func:`option_update_mask`; return ``delta [P, K]``.

        Args:
            q_head: any :class:`~skillchain_torch.options.OptionQHead` (``[P, K, A]`` values).
            obs, next_obs: ``[P, 4]`` observations of ``s`` and ``s'``.
            action: ``LongTensor [P]`` the primitive action taken in ``s`` (by anyone).
            reward: ``[P]`` or ``[P, 1]``.
            env_terminated: ``BoolTensor [P]`` or ``[P, 1]``; a truncated episode is *not*
                terminated and bootstraps.
            in_initiation: ``BoolTensor [P, K]``, ``s`` lies in option k's own initiation
                set; off-policy updates from outside it are ignored (paper 5.1).
            target_reached: ``BoolTensor [P, K]``, option k's termination predicate at ``s'``.
            learnable: ``BoolTensor [P, K]`` live slots (default all).
            code, next_code: ``q_head.encode`` of ``obs`` and ``next_obs`` when the caller
                already has them (an agent encodes each state once); then ``obs`` and
                ``next_obs`` are not read.
            executing: ``LongTensor [P]``, the slot that chose ``action`` (``-1``: none); it
                learns on-policy wherever ``s`` is.
            stepped: ``BoolTensor [P]``, the agents that took this step (default all); a head
                with a replay learner leaves the others' networks alone (an agent that has
                finished its episodes stops learning, as it would alone).

        Returns:
            the TD errors, 0 where nothing was updated.
        """
        population, slots = q_head.population, q_head.slots
        in_initiation = check_slot_mask(in_initiation, population, slots, "in_initiation")
        target_reached = check_slot_mask(target_reached, population, slots, "target_reached")
        if learnable is not None:
            learnable = check_slot_mask(learnable, population, slots, "learnable")
        if executing is not None and executing.numel() != population:
            raise ValueError(f"executing must be [P={population}], got {tuple(executing.shape)}")
        mask = option_update_mask(in_initiation, executing, learnable)
        for name, value in (("reward", reward), ("env_terminated", env_terminated)):
            if value.numel() != population:
                raise ValueError(f"{name} must be [P={population}], got {tuple(value.shape)}")
        replay = getattr(q_head, "replay", None)
        if replay is not None:  # stored with its mask, learned from in sampled minibatches
            return replay(q_head, obs, action, reward, next_obs, env_terminated,
                          target_reached, mask, self.gamma, self.completion_reward,
                          alive=stepped)  # fmt: skip
        if not bool(mask.any()):
            return torch.zeros(mask.shape, dtype=torch.float64, device=mask.device)
        checked = code is None  # a caller passing codes vouches for its inputs
        code = q_head.encode(obs) if code is None else code
        next_code = q_head.encode(next_obs) if next_code is None else next_code
        # Only the updated slots need max_a Q(s', a); others are masked out of the update.
        bootstrapped = mask & ~target_reached & ~env_terminated.reshape(-1, 1).to(torch.bool)
        next_q_max = q_head.max_values(next_code, bootstrapped)
        target = option_td_target(
            reward.to(next_q_max.device), next_q_max, target_reached.to(next_q_max.device),
            env_terminated.to(next_q_max.device), self.gamma, self.completion_reward,
        )  # fmt: skip
        if checked:
            return q_head.td_update(obs, action, target, mask.to(target.device))
        return q_head.td_update_code(code, action, target, mask.to(target.device))

    def extra_repr(self) -> str:
        return f"gamma={self.gamma}, completion_reward={self.completion_reward}"
