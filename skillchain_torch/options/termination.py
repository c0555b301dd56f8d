"""Termination predicates (target events): indicators of the observation (paper sections 4, 4.4).

An option's termination condition is the indicator ``T`` of its target event: the task's goal
(end of episode), another option's initiation set (skill chaining), or any user-given region or
function. Every predicate maps ``obs [P, 4]`` (and the env's ``terminated [P]`` flag, which only
:class:`GoalEvent` reads) to ``BoolTensor [P]`` and has a ``name`` for logging.

Example:
    >>> import torch
    >>> obs = torch.tensor([[0.9, 0.2, 0.5, 0.5], [0.1, 0.1, 0.5, 0.5]], dtype=torch.float64)
    >>> GoalEvent()(obs, torch.tensor([True, False])).tolist()
    [True, False]
    >>> RegionEvent(center=(0.9, 0.2), radius=0.05, name="corner")(obs).tolist()
    [True, False]
    >>> LambdaEvent(lambda o: o[:, 0] < 0.5, name="left")(obs).tolist()
    [False, True]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import torch
from torch import Tensor

from skillchain_torch.options.initiation import InitiationClassifier


@runtime_checkable
class TerminationPredicate(Protocol):
    """``predicate(obs [P, 4], terminated [P] | None = None) -> BoolTensor [P]``."""

    name: str

    def __call__(self, obs: Tensor, terminated: Tensor | None = None) -> Tensor: ...


def _check_obs(obs: Tensor) -> None:
    if obs.ndim != 2:
        raise ValueError(f"obs must be [P, D], got {tuple(obs.shape)}")


class GoalEvent:
    """The task's end-of-episode event: fires exactly when the environment terminated.

    In Pinball the only termination is reaching the hole, so the env's ``terminated`` flag is
    the goal indicator (truncation by a step limit is not the goal and does not fire).
    """

    def __init__(self, name: str = "goal"):
        self.name = name

    def __call__(self, obs: Tensor, terminated: Tensor | None = None) -> Tensor:
        _check_obs(obs)
        if terminated is None:
            raise ValueError("GoalEvent needs the environment's terminated flag")
        if terminated.numel() != obs.shape[0]:
            raise ValueError(f"terminated must be [P={obs.shape[0]}], got "
                             f"{tuple(terminated.shape)}")  # fmt: skip
        terminated = terminated.reshape(obs.shape[0])
        return terminated if terminated.dtype == torch.bool else terminated.to(torch.bool)

    def __repr__(self) -> str:
        return f"GoalEvent(name={self.name!r})"


class RegionEvent:
    """Fires inside a closed ball: ``||obs[dims] - center|| <= radius`` (Euclidean).

    Args:
        center: the centre in the chosen dims (a sequence, or a ``[P, len(dims)]`` tensor for a
            centre per agent).
        radius: the ball's radius in observation units.
        dims: observation dims the ball lives in; default ``(0, 1)``, the ball's position.
        name: for logging (default ``"region"``).
    """

    def __init__(self, center: Sequence[float] | Tensor, radius: float,
                 dims: Sequence[int] = (0, 1), name: str = "region"):  # fmt: skip
        self.dims = tuple(int(d) for d in dims)
        if not self.dims or any(d < 0 for d in self.dims):
            raise ValueError(f"dims must index the observation, got {self.dims}")
        self.center = torch.as_tensor(center, dtype=torch.float64)
        if self.center.shape[-1] != len(self.dims):
            raise ValueError(f"center has {self.center.shape[-1]} coordinates for dims "
                             f"{self.dims}")  # fmt: skip
        if radius < 0:
            raise ValueError("radius must be >= 0")
        self.radius = float(radius)
        self.name = name

    def __call__(self, obs: Tensor, terminated: Tensor | None = None) -> Tensor:
        _check_obs(obs)
        if max(self.dims) >= obs.shape[-1]:
            raise ValueError(f"{self.name}: dims {self.dims} do not index a "
                             f"{obs.shape[-1]}-d observation")  # fmt: skip
        center = self.center.to(device=obs.device, dtype=obs.dtype)
        diff = obs[:, self.dims] - center
        squared = diff[:, 0] * diff[:, 0]
        for j in range(1, len(self.dims)):  # fixed order: layout-invariant
            squared = squared + diff[:, j] * diff[:, j]
        return torch.sqrt(squared) <= self.radius

    def select_agents(self, rows: Sequence[int] | Tensor) -> RegionEvent:
        """The event of agents ``rows`` (repeats allowed), as ``OptionBank.select_agents``:
        a centre per agent keeps those rows' centres; one shared centre stays shared."""
        center = self.center
        if center.ndim == 2:
            center = center[torch.as_tensor(rows, dtype=torch.int64, device=center.device)]
        return RegionEvent(center, self.radius, self.dims, self.name)

    def __repr__(self) -> str:
        return f"RegionEvent(name={self.name!r}, dims={self.dims}, radius={self.radius})"


class InitiationSetEvent:
    """Another option's initiation set as a target event (skill chaining, section 4.2).

    Args:
        classifier: the population's :class:`InitiationClassifier`.
        slot: the target option's slot: an int for every agent or a ``LongTensor [P]`` (agents
            grow different chains); entries ``< 0`` never fire.
        name: for logging.

    Pass ``contains`` (the ``[P, K]`` result of ``classifier.contains(obs)`` already computed
    for action selection) to avoid evaluating the classifiers twice per state.
    """

    def __init__(self, classifier: InitiationClassifier, slot: int | Tensor,
                 name: str | None = None):  # fmt: skip
        self.classifier = classifier
        self.slot = torch.as_tensor(slot, dtype=torch.int64)
        if bool((self.slot >= classifier.slots).any()):
            raise ValueError(f"slot {self.slot.tolist()} out of range for K={classifier.slots}")
        self.name = name if name is not None else f"initiation[{self.slot.tolist()}]"

    def __call__(self, obs: Tensor, terminated: Tensor | None = None,
                 contains: Tensor | None = None) -> Tensor:  # fmt: skip
        member = self.classifier.contains(obs) if contains is None else contains
        slot = self.slot.to(member.device).expand(member.shape[0])
        fired = member.gather(1, slot.clamp(min=0)[:, None])[:, 0]
        return fired & (slot >= 0)

    def __repr__(self) -> str:
        return f"InitiationSetEvent(name={self.name!r})"


class LambdaEvent:
    """Any user indicator ``fn(obs [P, 4]) -> BoolTensor [P]`` as a target event (section 4.4)."""

    def __init__(self, fn: Callable[[Tensor], Tensor], name: str):
        self.fn = fn
        self.name = name

    def __call__(self, obs: Tensor, terminated: Tensor | None = None) -> Tensor:
        _check_obs(obs)
        fired = torch.as_tensor(self.fn(obs))
        if tuple(fired.shape) != (obs.shape[0],):
            raise ValueError(f"event {self.name!r} returned shape {tuple(fired.shape)}, "
                             f"expected [P={obs.shape[0]}]")  # fmt: skip
        return fired.to(torch.bool)

    def __repr__(self) -> str:
        return f"LambdaEvent(name={self.name!r})"


def evaluate_base_events(events: Sequence[TerminationPredicate], obs: Tensor,
                         terminated: Tensor, reward: Tensor | None = None) -> Tensor:  # fmt: skip
    """``BoolTensor [P, E]``: every base event's indicator at ``obs [P, 4]``; an event with
    ``wants_reward`` (a goal over the transition, :mod:`~skillchain_torch.options.goals`) also
    gets the transition's ``reward [P]``.

    Example:
        >>> obs = torch.tensor([[0.9, 0.2, 0.5, 0.5]], dtype=torch.float64)
        >>> evaluate_base_events((GoalEvent(), RegionEvent((0.9, 0.2), 0.05)), obs,
        ...                      torch.tensor([False])).tolist()
        [[False, True]]
    """
    if not events:
        return torch.zeros(obs.shape[0], 0, dtype=torch.bool, device=obs.device)
    if len(events) == 1:  # the paper's goal alone, every step: a view, not a stack
        fired = _fire(events[0], obs, terminated, reward)
        return (fired if fired.device == obs.device else fired.to(obs.device)).unsqueeze(-1)
    return torch.stack([_fire(e, obs, terminated, reward).to(obs.device) for e in events],
                       dim=-1)  # fmt: skip


def _fire(event: TerminationPredicate, obs: Tensor, terminated: Tensor,
          reward: Tensor | None) -> Tensor:  # fmt: skip
    if getattr(event, "wants_reward", False):
        return event(obs, terminated, reward)
    return event(obs, terminated)
