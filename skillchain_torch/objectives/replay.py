"""Experience replay for a loss module: how a neural head learns from more than the last step.

The paper's linear learners update once per transition. A neural head trained that way forgets
and chases its own tail; DQN's remedy is a replay buffer and a target network. :class:`ReplayTD`
is that remedy for any loss module of this package, built from TorchRL's pieces: a
``ReplayBuffer`` over a ``LazyTensorStorage``, sampled by its own ``torch.Generator`` (so the
global RNG is never touched and a seed gives the same run), and ``HardUpdate`` for the target
parameters of a loss made with ``delay_value=True``.

**Per agent of the population.** Each stored item is one population step, a TensorDict of
batch ``[P]`` with an ``active`` mask (the agents whose decision ended there). A minibatch is
``[B, P]``: ``B`` stored steps, each agent's rows its own transitions, inactive rows masked out
of the loss, which sums over agents; so agent p's network learns only from agent p's past.

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> from skillchain_torch.modules import MLPQHead
    >>> from skillchain_torch.objectives import SMDPSarsaLoss
    >>> head = MLPQHead(num_features=2, num_decisions=3, population=2, hidden=8, value_scale=10.0)
    >>> loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=10.0, delay_value=True)
    >>> learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=1e-2), batch_size=4)
    >>> td = TensorDict(phi=torch.zeros(2, 2, dtype=torch.float64), decision=torch.tensor([0, 1]),
    ...                 decision_return=torch.tensor([-1.0, 5.0], dtype=torch.float64),
    ...                 duration=torch.tensor([1, 1]),
    ...                 next_value=torch.zeros(2, dtype=torch.float64),
    ...                 terminated=torch.tensor([True, True]), active=torch.tensor([True, True]),
    ...                 next_phi=torch.zeros(2, 2, dtype=torch.float64),
    ...                 next_decision=torch.tensor([0, 0]), batch_size=[2])
    >>> for _ in range(200):
    ...     delta = learner(td)
    >>> [round(v) for v in head.q_value(td["phi"], td["decision"]).tolist()]
    [-1, 5]
"""

from __future__ import annotations

import logging

import torch
from tensordict import TensorDictBase
from torch import Tensor
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.objectives import HardUpdate, LossModule

__all__ = ["ReplayTD", "seeded_buffer", "store"]


def seeded_buffer(capacity: int, batch_size: int,
                  seed: int) -> tuple[ReplayBuffer, torch.Generator]:  # fmt: skip
    """A TorchRL replay buffer over a ``LazyTensorStorage`` sampled by a generator of its own
    (seeded ``seed``), so the global RNG is never touched; ``(buffer, generator)``."""
    generator = torch.Generator().manual_seed(int(seed))
    buffer = ReplayBuffer(storage=LazyTensorStorage(int(capacity)), batch_size=int(batch_size),
                          generator=generator)  # fmt: skip
    return buffer, generator


def store(buffer: ReplayBuffer, item: TensorDictBase) -> None:
    """Add one population step ``item [P]`` to ``buffer`` as one element, without TorchRL's
    INFO line when the first one allocates the storage (it would break a run's quiet output)."""
    logger = logging.getLogger("torchrl")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        buffer.extend(item.unsqueeze(0))
    finally:
        logger.setLevel(level)


class ReplayTD:
    """A learner (:class:`~skillchain_torch.interfaces.Learner`): store, sample, step.

    Args:
        loss: a loss module over ``[*B, P]`` TensorDicts (e.g. :class:`SMDPSarsaLoss`); with
            target parameters (``delay_value=True``) they are copied every ``target_update``
            optimizer steps (TorchRL's ``HardUpdate``).
        optimizer: over the head's parameters.
        capacity: population steps kept (the oldest go first).
        batch_size: B, population steps per minibatch.
        warmup: steps stored before the first update (default ``batch_size``).
        target_update: optimizer steps between target copies.
        train_every: one optimizer step per this many stored steps (DQN's train frequency).
        seed: of the sampling generator.

    ``learner(td [P])`` stores ``td`` if any agent is active, takes an optimizer step on a
    minibatch every ``train_every`` stored steps once ``warmup`` are stored, and returns
    ``td``'s TD errors ``[P]`` toward its ``next_value`` (the loss's :meth:`td_error` when it
    has one: the online parameters before the step; 0 for inactive agents).
    """

    def __init__(self, loss: LossModule, optimizer: torch.optim.Optimizer, capacity: int = 50_000,
                 batch_size: int = 32, warmup: int | None = None, target_update: int = 500,
                 train_every: int = 1, seed: int = 0):  # fmt: skip
        if min(capacity, batch_size, target_update, train_every) < 1:
            raise ValueError("capacity, batch_size, target_update and train_every must be >= 1")
        self.loss, self.optimizer = loss, optimizer
        self.batch_size = int(batch_size)
        self.warmup = self.batch_size if warmup is None else int(warmup)
        self.buffer, self.generator = seeded_buffer(capacity, self.batch_size, seed)
        targets = any(name.startswith("target_") for name, _ in loss.named_children())
        self.updater = (HardUpdate(loss, value_network_update_interval=int(target_update))
                        if targets else None)  # fmt: skip
        self.train_every, self.stored, self.updates = int(train_every), 0, 0
        self._writes = 0  # the head's set_values count when the target was last copied

    def __call__(self, td: TensorDictBase) -> Tensor:
        if hasattr(self.loss, "td_error"):
            delta = self.loss.td_error(td)
        else:
            with torch.no_grad():
                delta = self.loss(td)["td_error"]
        if not bool(td.get("active").any()):
            return delta
        store(self.buffer, td.detach().clone())
        self.stored += 1
        if len(self.buffer) >= self.warmup and self.stored % self.train_every == 0:
            batch = self.buffer.sample()
            self.optimizer.zero_grad()
            self.loss(batch)["loss"].backward()
            self.optimizer.step()
            self.updates += 1
            if self.updater is not None:
                self.updater.step()
        writes = int(getattr(getattr(self.loss, "value_head", None), "writes", 0))
        if writes != self._writes and self.updater is not None:
            # Discovery set a joining option's value: the target copy takes it now, or targets
            # would bootstrap from the slot's stale value until the next scheduled copy.
            for name, target in self.loss.named_children():
                if name.startswith("target_"):
                    target.data.copy_(getattr(self.loss, name[len("target_"):]).data)
            self._writes = writes
        return delta

    def state_dict(self) -> dict:
        return {"buffer": self.buffer.state_dict(), "optimizer": self.optimizer.state_dict(),
                "generator": self.generator.get_state(), "updates": self.updates,
                "stored": self.stored, "writes": self._writes,
                "targets": self.loss.state_dict(),
                "counter": getattr(self.updater, "counter", 0)}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        self.buffer.load_state_dict(state["buffer"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])
        self.updates, self.stored = int(state["updates"]), int(state["stored"])
        self._writes = int(state.get("writes", 0))
        self.loss.load_state_dict(state["targets"])
        if self.updater is not None:
            self.updater.counter = int(state["counter"])

