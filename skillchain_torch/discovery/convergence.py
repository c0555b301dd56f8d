"""When an initiation set counts as learned (paper section 5.1).

"We considered an option's initiation set learned well enough to be added to the list of
target events when its weights changed on average less than 0.15 per episode for two
consecutive episodes."

The change of an episode is the mean absolute change of the classifier's weights (bias
included) between the episode's start and end
(:meth:`~skillchain_torch.options.InitiationClassifier.weight_change`). Only episodes in which
the classifier was refitted count: an option that was not executed did not change because it
learned nothing, not because it converged (counting those would declare a never-tried option
learned after two idle episodes). A counted episode below the threshold extends the streak,
one above resets it. An option also needs at least one positive example: with the distance
constraint a set without positives would be empty.

Example:
    >>> import torch
    >>> test = ConvergenceTest(population=1, slots=2)
    >>> counted = torch.tensor([[True, True]])
    >>> test.update(torch.tensor([[0.1, 0.5]]), counted).tolist()
    [[False, False]]
    >>> test.update(torch.tensor([[0.1, 0.1]]), counted).tolist()       # slot 0: twice
    [[True, False]]
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["CONVERGENCE_THRESHOLD", "CONVERGENCE_EPISODES", "ConvergenceTest"]

CONVERGENCE_THRESHOLD = 0.15
CONVERGENCE_EPISODES = 2


class ConvergenceTest:
    """Per-slot streaks of counted episodes with a small classifier change.

    Args:
        population, slots: P and K.
        threshold: the largest mean weight change per episode that counts as converged.
        episodes: consecutive counted episodes needed.

    State: ``streak [P, K]`` (int64), in :meth:`state_dict`.
    """

    def __init__(self, population: int, slots: int, threshold: float = CONVERGENCE_THRESHOLD,
                 episodes: int = CONVERGENCE_EPISODES, device=None):  # fmt: skip
        if threshold <= 0 or episodes < 1:
            raise ValueError("need threshold > 0 and episodes >= 1")
        self.threshold, self.episodes = float(threshold), int(episodes)
        self.streak = torch.zeros(population, slots, dtype=torch.int64, device=device)

    def update(self, change: Tensor, counted: Tensor) -> Tensor:
        """Fold in one episode: ``change [P, K]`` for the slots in ``counted [P, K]``;
        returns the slots whose streak now reaches ``episodes``."""
        small = change < self.threshold
        grown = torch.where(small, self.streak + 1, torch.zeros_like(self.streak))
        self.streak = torch.where(counted, grown, self.streak)
        return counted & (self.streak >= self.episodes)

    def reset(self, mask: Tensor) -> None:
        """Forget the streaks of ``mask [P, K]`` (a new option in the slot)."""
        self.streak = torch.where(mask, torch.zeros_like(self.streak), self.streak)

    def state_dict(self) -> dict[str, Tensor]:
        return {"streak": self.streak.clone()}

    def load_state_dict(self, state: dict[str, Tensor]) -> None:
        self.streak = state["streak"].to(self.streak.device).clone()
