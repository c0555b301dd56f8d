"""Learning initiation sets from executions (paper sections 4.1 and 5.1).

"When the agent executed the option, states on trajectories that reached its goal within 250
steps were used as positive examples, and the start states of trajectories that did not were
used as negative examples." And: "updates from unsuccessful on-policy trajectories" were
ignored, "because their start states were then removed from the initiation set".

:class:`ExecutionTrace` follows the execution in progress of every agent: the states it acted
in (at most ``max_steps``) and a copy of the option's Q-head slot taken when it started. When
the execution ends:

* *success*, the option's target event fired at ``s'``: every state it acted in is a
  positive example;
* *failure*, it ran ``max_steps`` steps, or the episode terminated elsewhere than at its
  target: its start state is a negative example, and the option's Q-head slot is put back as
  it was at the start, dropping the updates of the failed trajectory;
* neither, when an episode *truncation* (a step limit of the environment, not of the option)
  cut it short: it was not given its 250 steps, so it teaches nothing either way.

Example:
    >>> import torch
    >>> success, failure = execution_outcome(
    ...     reached=torch.tensor([True, False, False, False]),
    ...     duration=torch.tensor([3, 250, 7, 7]),
    ...     terminated=torch.tensor([False, False, True, False]), max_steps=250)
    >>> success.tolist(), failure.tolist()     # target, timeout, episode over, truncated
    ([True, False, False, False], [False, True, True, False])
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as backend
from skillchain_torch.backends import initiation as initiation_backend
from skillchain_torch.options import InitiationClassifier, OptionQHead

__all__ = ["OUTCOMES", "ExecutionCounts", "execution_outcome", "ExecutionTrace"]

# How an execution ends, as counted per agent-episode (ExecutionCounts, the run's
# option_outcomes.npy): its target fired; it ran max_steps; the episode terminated elsewhere.
# (An execution cut by a truncated episode is neither success nor failure: its steps count,
# its outcome does not.)
OUTCOMES = ("success", "timeout", "episode_end")

OBS_DIM = 4


def execution_outcome(reached: Tensor, duration: Tensor, terminated: Tensor,
                      max_steps: int) -> tuple[Tensor, Tensor]:  # fmt: skip
    """``(success, failure)`` of executions that just ended (all ``[P]``).

    Args:
        reached: the executing option's target fired at ``s'``.
        duration: steps the execution ran, this one included.
        terminated: the episode terminated at ``s'``.
        max_steps: the option's step limit (paper: 250).
    """
    success = reached
    failure = ~reached & ((duration >= max_steps) | terminated)
    return success, failure


class ExecutionTrace:
    """The states of every agent's execution in progress, and its option's starting weights.

    Args:
        population: P; max_steps: the longest execution (paper: 250).
        q_head: the options' :class:`~skillchain_torch.options.OptionQHead` (for the snapshot).

    State (:meth:`state_dict`): ``states [P, max_steps, D]`` and ``snapshot`` (the Q-head
    slot of the executing option at its start, per agent).
    """

    def __init__(self, population: int, max_steps: int, q_head: OptionQHead,
                 dtype=torch.float64, device=None):  # fmt: skip
        self.max_steps = int(max_steps)
        self.q_head = q_head
        self.states = torch.zeros(population, self.max_steps, q_head.obs_dim, dtype=dtype,
                                  device=device)  # fmt: skip
        slot = torch.zeros(population, dtype=torch.int64, device=device)
        self.snapshot = q_head.read_slots(slot)
        self._agents = torch.arange(population, device=device)

    def start(self, rows: Tensor, slot: Tensor) -> None:
        """Agents in ``rows [P]`` start executing option ``slot [P]``: keep its weights."""
        tensors = self.q_head.slot_tensors()
        if all(backend.copy_slots(value, rows, slot, self.snapshot[name], False)
               for name, value in tensors.items()):  # fmt: skip
            return  # one compiled copy per tensor
        index = rows.nonzero()[:, 0]
        if index.numel() == 0:
            return
        # Copy just the starting agents' slots (a few rows of [P, ...] weights).
        k = slot[index].clamp(min=0)
        for name, value in tensors.items():
            self.snapshot[name][index] = value[index, k].to(self.snapshot[name].dtype)

    def record(self, rows: Tensor, step: Tensor, obs: Tensor) -> None:
        """Agents in ``rows [P]`` act in ``obs [P, 4]`` as step ``step [P]`` (0-based)."""
        if (self.states.dtype == torch.float64 and self.states.shape[-1] == OBS_DIM
                and backend.NATIVE and backend.applies(self.states, rows)):  # fmt: skip
            backend.record(self.states, rows, step, obs)
            return
        index = rows.nonzero()[:, 0]
        self.states[index, step[index].clamp(max=self.max_steps - 1)] = obs[index].to(
            self.states.dtype)

    def examples(self, slot: Tensor, duration: Tensor, success: Tensor,
                 failure: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:  # fmt: skip
        """Initiation-set examples of ended executions, in agent order.

        Returns ``(agents [N], slots [N], obs [N, 4], labels [N])``: the ``duration`` states
        of each successful execution (positive), the start state of each failed one (negative).
        """
        steps = torch.arange(self.max_steps, device=slot.device)
        positive = success[:, None] & (steps < duration[:, None])
        negative = failure[:, None] & (steps == 0)
        take = positive | negative  # [P, T]
        agents, step = take.nonzero().unbind(-1)
        return agents, slot[agents], self.states[agents, step], positive[agents, step]

    def store_examples(self, classifier: InitiationClassifier, slot: Tensor, duration: Tensor,
                       success: Tensor, failure: Tensor) -> Tensor:  # fmt: skip
        """Add the :meth:`examples` of ended executions to ``classifier`` (slot ``slot [P]``
        of each agent); the ``[P, K]`` mask of slots that received data.

        A compiled classifier stores them straight from the trace (the same examples in the
        same order, so the same stores)."""
        if (classifier.native and self.states.dtype == torch.float64
                and self.states.shape[-1] == OBS_DIM):  # fmt: skip
            touched = torch.zeros(classifier.population, classifier.slots, dtype=torch.bool)
            initiation_backend.store_executions(classifier.stores, self.states, slot, duration,
                                                success, failure, touched)  # fmt: skip
            classifier.dirty |= touched
            return touched
        agents, slots, obs, labels = self.examples(slot, duration, success, failure)
        if agents.numel() == 0:
            return torch.zeros_like(classifier.dirty)
        return classifier.add_examples(agents, slots, obs, labels)

    def drop_updates(self, slot: Tensor, failure: Tensor) -> None:
        """Put the options of failed executions back as they were when they started."""
        tensors = self.q_head.slot_tensors()
        if all(backend.copy_slots(value, failure, slot, self.snapshot[name], True)
               for name, value in tensors.items()):  # fmt: skip
            return
        self.q_head.write_slots(slot, self.snapshot, failure)

    def state_dict(self) -> dict:
        return {"states": self.states.clone(),
                "snapshot": {k: v.clone() for k, v in self.snapshot.items()}}

    def load_state_dict(self, state: dict) -> None:
        device = self.states.device
        self.states = state["states"].to(device).clone()
        self.snapshot = {k: v.to(device).clone() for k, v in state["snapshot"].items()}


class ExecutionCounts:
    """How each agent's option executions ended this episode, per slot: ``outcomes [P, K, 3]``
    (:data:`OUTCOMES`) and ``steps [P, K]`` (their durations). At an agent's episode end they
    become its ``last_outcomes`` / ``last_steps`` (what the trainer's monitors read) and start
    again. Kept by discovery, where executions end anyway, so monitoring needs no per-step work.

    Example:
        >>> counts = ExecutionCounts(population=2, slots=2)
        >>> counts.add(torch.tensor([True, False]), torch.tensor([1, 0]),
        ...            torch.tensor([True, False]), torch.tensor([False, False]),
        ...            torch.tensor([False, False]), torch.tensor([12, 3]))
        >>> counts.end_episodes(torch.tensor([True, True]))
        >>> counts.last_outcomes[0, 1].tolist(), counts.last_steps.tolist()
        ([1, 0, 0], [[0, 12], [0, 0]])
        >>> int(counts.steps.sum())  # the new episodes' counts start at 0
        0
    """

    def __init__(self, population: int, slots: int, device=None):
        i64 = dict(dtype=torch.int64, device=device)
        self.outcomes = torch.zeros(population, slots, len(OUTCOMES), **i64)
        self.steps = torch.zeros(population, slots, **i64)
        self.last_outcomes, self.last_steps = self.outcomes.clone(), self.steps.clone()

    def add(self, done: Tensor, slot: Tensor, success: Tensor, timeout: Tensor,
            episode_end: Tensor, duration: Tensor) -> None:  # fmt: skip
        """Rows ``done [P]`` ended an execution of ``slot [P]`` after ``duration [P]`` steps,
        with the outcome flags given (all ``[P]``; none set: a truncated episode)."""
        rows = done.nonzero()[:, 0]
        if rows.numel() == 0:
            return
        k = slot[rows]
        kinds = torch.stack([success, timeout, episode_end], 1)[rows].to(torch.int64)
        self.outcomes[rows, k] += kinds
        self.steps[rows, k] += duration[rows].to(torch.int64)

    def end_episodes(self, rows: Tensor) -> None:
        """Agents ``rows [P]`` ended an episode: their counts become the last episode's."""
        keep = rows[:, None]
        self.last_steps = torch.where(keep, self.steps, self.last_steps)
        self.last_outcomes = torch.where(keep[..., None], self.outcomes, self.last_outcomes)
        self.steps = torch.where(keep, torch.zeros_like(self.steps), self.steps)
        self.outcomes = torch.where(keep[..., None], torch.zeros_like(self.outcomes),
                                    self.outcomes)  # fmt: skip

    _STATE = ("outcomes", "steps", "last_outcomes", "last_steps")

    def state_dict(self) -> dict:
        return {name: getattr(self, name).clone() for name in self._STATE}

    def load_state_dict(self, state: dict) -> None:
        device = self.steps.device
        for name in self._STATE:
            setattr(self, name, state[name].to(device).clone())
