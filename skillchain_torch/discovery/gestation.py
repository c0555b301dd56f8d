"""Gestation and the initial value of a new option (paper section 5.1).

"A newly created option was first allowed a gestation period of 10 episodes where it could not
be executed and its policy was updated using only off-policy learning. After its gestation
period, the option was added to the agent's action repertoire [...] We therefore sampled the Q
values of transitions that triggered the option's target event during its gestation, and
initialized Q(s, o) to the maximum of these values."

* An option created during episode ``e`` gestates through the rest of ``e`` and the ten whole
  episodes after it: at the end of episode ``e + gestation`` it becomes LEARNING (executable).
* The samples are the top-level ``Q(s, d)`` of the decision ``d`` in force at ``s`` on each
  transition ``s -> s'`` that triggered the option's target event, the creating transition
  included (so there is always at least one).
* ``Q(s, o)`` is linear in Fourier features whose first feature is the constant 1
  (coefficient vector 0), so "initialised to a value" means that weight set to it and the
  others to 0: ``Q(s, o) = value`` everywhere.

Example:
    >>> import torch
    >>> from skillchain_torch.modules import LinearQHead
    >>> head = LinearQHead(num_features=3, num_decisions=5 + 2, population=1)
    >>> initialise_option_values(head, torch.tensor([[False, True]]),
    ...                          torch.tensor([[0.0, 7.5]], dtype=torch.float64))
    >>> head(torch.tensor([[1.0, 0.3, -0.2]], dtype=torch.float64)).tolist()
    [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 7.5]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import OptionBank, OptionStatus

__all__ = ["GESTATION_EPISODES", "RecentStates", "gestation_over", "initialise_option_values"]

GESTATION_EPISODES = 10
NUM_PRIMITIVES = 5


def gestation_over(bank: OptionBank, episode: Tensor, ended: Tensor,
                   gestation: int = GESTATION_EPISODES) -> Tensor:  # fmt: skip
    """``[P, K]``: gestating options that join the repertoire now.

    Args:
        episode: ``LongTensor [P]``, the 0-based index of the episode that just ended.
        ended: ``BoolTensor [P]``, agents whose episode just ended.
        gestation: whole episodes of gestation after the creating one (paper: 10).
    """
    due = (episode[:, None] - bank.created_episode) >= gestation
    return ended[:, None] & (bank.status == OptionStatus.GESTATING) & due


@torch.no_grad()
def initialise_option_values(q_head: LinearQHead, mask: Tensor, value: Tensor,
                             num_primitives: int = NUM_PRIMITIVES) -> None:  # fmt: skip
    """Set ``Q(s, o_k) = value[p, k]`` for every state, for the slots in ``mask [P, K]``.

    The top-level head holds decisions ``num_primitives + k``; feature 0 must be the constant
    (true of :class:`~skillchain_torch.features.FourierBasis`).
    """
    weights = q_head.weight[:, num_primitives:, :]  # [P, K, F] view
    init = torch.zeros_like(weights)
    init[..., 0] = value.to(weights.dtype)
    weights.copy_(torch.where(mask[..., None], init, weights))


class RecentStates:
    """The last ``length`` states of every agent's current episode, for gestation positives.

    Deep skill chaining (Bagaria & Konidaris) makes a new option's initiation set local from
    the start: during gestation, each time the option's target fires, the states that led to it
    become positive examples. :meth:`record` keeps a ring of the states each agent acted in
    this episode; :meth:`window` reads the last ``n`` of them, oldest first.

    Example:
        >>> import torch
        >>> recent = RecentStates(population=2, length=3)
        >>> for t in range(4):
        ...     recent.record(torch.tensor([True, t < 1]), torch.full((2, 4), float(t)))
        >>> agents, obs = recent.window(torch.tensor([True, True]), 3)
        >>> agents.tolist(), obs[:, 0].tolist()           # agent 0: t = 1..3; agent 1: t = 0
        ([0, 0, 0, 1], [1.0, 2.0, 3.0, 0.0])
    """

    def __init__(self, population: int, length: int, dtype=torch.float64, device=None):
        if length < 1:
            raise ValueError(f"RecentStates needs length >= 1, got {length}")
        self.length = int(length)
        self.states = torch.zeros(population, self.length, 4, dtype=dtype, device=device)
        self.steps = torch.zeros(population, dtype=torch.int64, device=device)  # this episode

    def record(self, rows: Tensor, obs: Tensor) -> None:
        """Agents in ``rows [P]`` act in ``obs [P, 4]`` (the state a transition starts from)."""
        index = rows.nonzero()[:, 0]
        if index.numel() == 0:
            return
        self.states[index, self.steps[index] % self.length] = obs[index].to(self.states.dtype)
        self.steps[index] += 1

    def start_episodes(self, rows: Tensor) -> None:
        """Agents in ``rows [P]`` start an episode: their earlier states no longer count."""
        self.steps = torch.where(rows, torch.zeros_like(self.steps), self.steps)

    def window(self, rows: Tensor, n: int) -> tuple[Tensor, Tensor]:
        """``(agents [M], obs [M, 4])``: the last ``min(n, length, steps)`` states of each agent
        in ``rows [P]``, oldest first, agents in ascending order."""
        n = min(int(n), self.length)
        index = rows.nonzero()[:, 0]
        taken = self.steps[index].clamp(max=n)  # [A]
        back = torch.arange(n, 0, -1, device=self.steps.device)  # n .. 1 steps back
        keep = back[None, :] <= taken[:, None]  # [A, n]
        place = (self.steps[index, None] - back[None, :]) % self.length
        agent = index[:, None].expand(-1, n)
        return agent[keep], self.states[agent[keep], place[keep]]

    def state_dict(self) -> dict:
        return {"states": self.states.clone(), "steps": self.steps.clone()}

    def load_state_dict(self, state: dict) -> None:
        device = self.steps.device
        self.states = state["states"].to(device).clone()
        self.steps = state["steps"].to(device).clone()
