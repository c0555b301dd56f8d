"""Each agent's own replay memory: what makes the runs of a population independent samples.

A population of P agents is P independent runs of one experiment, and the intervals over runs
assume that they are. A replay memory shared by the population breaks this even when each
agent learns only from its own transitions: if the memory stores a population step whenever
*some* agent's decision ended and draws one set of indices for all agents, then when agent q
stores, finishes or leaves changes which of agent p's transitions p replays. (Measured on
neural skill chaining, Pinball: 8 of 10 agents of a 20-episode run differed from the same
agents of a 50-episode run from the episode in which the fastest agent finished.)

:class:`AgentReplayStorage` gives agent p a ring of its own, ``capacity`` places in one
TorchRL ``LazyTensorStorage`` of ``P * capacity`` rows (agent p's ring is rows ``p *
capacity`` onward), written at agent p's own cursor and sampled by agent p's own
:class:`~skillchain_torch.rng.CounterRNG` stream (seed ``S + p``), so agent p's minibatches
depend on agent p's transitions and seed alone.

Why not TorchRL's ``ReplayBuffer`` around the storage: it has one write cursor and one sampler
over the whole storage; the agent is a dimension here, with a cursor, a size and a random
stream per agent. The storage is TorchRL's, the interface follows its ``add``/``sample``/
``state_dict`` conventions.

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> memory = AgentReplayStorage(capacity=4, batch_size=3, seed=0, stream=1)
    >>> item = TensorDict(x=torch.tensor([1.0, 2.0]), batch_size=[2])
    >>> memory.add(item, torch.tensor([True, False]))     # only agent 0 stored a transition
    >>> memory.count.tolist()
    [1, 0]
    >>> batch = memory.sample(memory.count >= 1)          # [B, P]: agent 1's rows are not real
    >>> batch.shape, batch["x"][:, 0].tolist()
    (torch.Size([3, 2]), [1.0, 1.0, 1.0])
"""

from __future__ import annotations

import logging

import torch
from tensordict import TensorDictBase
from torch import Tensor
from torchrl.data import LazyTensorStorage

from skillchain_torch.options.status import agent_seeds
from skillchain_torch.rng import CounterRNG

__all__ = ["AgentReplayStorage", "saved_memory"]

SHARED_FORMAT = ("this checkpoint's replay memory is shared by the population (saved before "
                 "per-agent replay, results/neural/README.md): it cannot be resumed; re-run the "
                 "command without --resume")


def saved_memory(state: dict) -> dict:
    """A learner's saved :class:`AgentReplayStorage` state (``state["memory"]``); a learner
    saved before per-agent replay is refused in one line."""
    if "memory" not in state:
        raise ValueError(SHARED_FORMAT)
    return state["memory"]


class AgentReplayStorage:
    """Per-agent rings of transitions in one TorchRL ``LazyTensorStorage``.

    Args:
        capacity: transitions kept per agent (its oldest go first).
        batch_size: B, transitions per agent per minibatch.
        seed: int (agent p samples with seed ``seed + p``) or ``LongTensor [P]`` of per-agent
            seeds; the population comes from the first :meth:`add`.
        stream: the :class:`~skillchain_torch.rng.CounterRNG` stream (a learner's own salt, so
            two memories of one agent draw different numbers).

    The storage is allocated, zero-filled, at the first :meth:`add` (zeros, not ``torch.empty``:
    a masked-out row must stay finite, since ``0 * nan`` in a backward pass is ``nan``).
    """

    def __init__(self, capacity: int, batch_size: int, seed: int | Tensor = 0, stream: int = 0):
        if min(capacity, batch_size) < 1:
            raise ValueError(f"capacity and batch_size must be >= 1, got {capacity}, {batch_size}")
        self.capacity, self.batch_size = int(capacity), int(batch_size)
        self.seed, self.stream = seed, int(stream)
        self.storage: LazyTensorStorage | None = None
        self.count: Tensor | None = None  # [P] transitions each agent has stored, ever
        self.rng: CounterRNG | None = None

    @property
    def started(self) -> bool:
        return self.count is not None

    def _start(self, item: TensorDictBase) -> None:
        P, device = item.shape[0], item.device
        if device is None:  # a TensorDict without a device: its first tensor's
            device = next(iter(item.values(include_nested=True, leaves_only=True))).device
        self.storage = LazyTensorStorage(P * self.capacity, device=device)
        zeros = item[:1].clone().zero_().expand(P * self.capacity)
        logger = logging.getLogger("torchrl")  # (its INFO line on allocation would break a
        level = logger.level                   # run's quiet output)
        logger.setLevel(max(level, logging.WARNING))
        try:
            self.storage.set(torch.arange(P * self.capacity, device=device), zeros)
        finally:
            logger.setLevel(level)
        self.count = torch.zeros(P, dtype=torch.int64, device=device)
        seeds = agent_seeds(self.seed.cpu() if isinstance(self.seed, Tensor) else self.seed, P)
        self.rng = CounterRNG(seeds.to(device), stream=self.stream)

    def add(self, item: TensorDictBase, rows: Tensor) -> None:
        """Store row p of ``item [P]`` in agent p's ring, for the agents in ``rows [P]``."""
        if self.count is None:
            self._start(item)
        agents = rows.to(torch.bool).nonzero()[:, 0]
        if agents.numel() == 0:
            return
        places = agents * self.capacity + self.count[agents] % self.capacity
        self.storage.set(places, item[agents])
        self.count[agents] += 1

    def sizes(self) -> Tensor:
        """``[P]``: transitions each agent holds now."""
        return self.count.clamp(max=self.capacity)

    def sample(self, rows: Tensor) -> TensorDictBase:
        """A minibatch ``[B, P]``: column p is B transitions drawn uniformly from agent p's ring,
        for the agents in ``rows [P]`` (only their streams advance). The other columns hold
        finite rows that are not theirs: the caller masks them out."""
        rows = rows.to(torch.bool)
        P = self.count.shape[0]
        index = self.rng.integers(self.batch_size, high=self.sizes().clamp(min=1), mask=rows)
        index = torch.where(rows[:, None], index, torch.zeros_like(index))  # [P, B]
        first = torch.arange(P, device=index.device)[:, None] * self.capacity
        return self.storage.get((first + index).T.contiguous())

    def state_dict(self) -> dict:
        return {"format": "per-agent", "capacity": self.capacity,
                "storage": None if self.storage is None else self.storage.state_dict(),
                "count": self.count, "rng": None if self.rng is None else self.rng.state_dict()}

    def load_state_dict(self, state: dict, device: torch.device | str | None = None) -> None:
        """Restore :meth:`state_dict`'s state, on ``device`` (default: where it was saved; a
        checkpoint read with ``map_location="cpu"`` needs the learner's device here)."""
        if state.get("format") != "per-agent":
            raise ValueError(SHARED_FORMAT)
        if int(state["capacity"]) != self.capacity:
            raise ValueError(f"checkpoint replay capacity {state['capacity']} != {self.capacity}")
        if state["storage"] is None:
            self.storage = self.count = self.rng = None
            return
        device = state["count"].device if device is None else torch.device(device)
        self.count = state["count"].clone().to(device)
        P = self.count.shape[0]
        saved = LazyTensorStorage(P * self.capacity)
        saved.load_state_dict(state["storage"])
        if torch.device(saved.device) == device:
            self.storage = saved
        else:  # moved through the storage's own get/set (its layout stays TorchRL's business)
            places = torch.arange(P * self.capacity)
            self.storage = LazyTensorStorage(P * self.capacity, device=device)
            self.storage.set(places.to(device), saved.get(places).to(device))
        self.rng = CounterRNG(torch.zeros(P, dtype=torch.int64))
        self.rng.load_state_dict(state["rng"])
        self.rng.to(device)
