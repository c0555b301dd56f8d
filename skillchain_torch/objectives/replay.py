"""Experience replay for a loss module: how a neural head learns from more than the last step.

The paper's linear learners update once per transition. A neural head trained that way forgets
and chases its own tail; DQN's remedy is a replay buffer and a target network. :class:`ReplayTD`
is that remedy for any loss module of this package, built from TorchRL's pieces: a
``LazyTensorStorage`` (one ring per agent, sampled by counter-based streams: the global RNG is
never touched and a seed gives the same run), and ``HardUpdate`` for the target parameters of
a loss made with ``delay_value=True``.

**Per agent of the population.** Each agent stores its own transitions (the rows whose
``active`` flag is set: its decision ended there) in a memory of its own and samples them by a
random stream of its own (:class:`~skillchain_torch.objectives.agent_storage.
AgentReplayStorage`). A minibatch is ``[B, P]``: column p is B of agent p's transitions,
masked out of the loss until agent p holds ``warmup`` of them; the loss sums over agents. The
schedule reads the population step, which is every agent's own step count (every active agent
steps once per population step), so an agent's updates, target copies and optimizer step
count are the same in any population: its run depends on its seed alone.

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

import torch
from tensordict import TensorDictBase
from torch import Tensor
from torchrl.objectives import HardUpdate, LossModule

from skillchain_torch.objectives.agent_storage import AgentReplayStorage, saved_memory

__all__ = ["ReplayTD"]

STREAM = 0x5EB  # the top level's replay draws (a CounterRNG stream of its own)


class ReplayTD:
    """A learner (:class:`~skillchain_torch.interfaces.Learner`): store, sample, step.

    Args:
        loss: a loss module over ``[*B, P]`` TensorDicts (e.g. :class:`SMDPSarsaLoss`); with
            target parameters (``delay_value=True``) they are copied every ``target_update``
            optimizer steps (TorchRL's ``HardUpdate``).
        optimizer: over the head's parameters.
        capacity: transitions kept per agent (its oldest go first).
        batch_size: B, transitions per agent per minibatch.
        warmup: an agent's transitions stored before it learns (default ``batch_size``).
        target_update: optimizer steps between target copies.
        train_every: one optimizer step per this many calls (population steps: DQN's train
            frequency, counted in the agent's own steps).
        seed: int (agent p samples with ``seed + p``) or ``LongTensor [P]`` of agent seeds.

    ``learner(td [P])`` stores the active agents' rows, takes an optimizer step every
    ``train_every`` calls on each agent's own minibatch (of the agents in ``td["stepped"]``
    when it has that key: an agent that finished its episodes stops learning, and its
    weights, stacked ``[P, ...]``, are held where they are through the step, since Adam's
    momentum would move them on zero gradients), and returns ``td``'s TD errors ``[P]``
    toward its ``next_value`` (the loss's :meth:`td_error` when it has one: the online
    parameters before the step; 0 for inactive agents).

    The optimizer steps at every ``train_every``-th call even while no agent has learned yet
    (zero gradients), so its step count, which Adam's bias correction reads, is a function of
    the call count alone. An agent that is not yet warm gets exactly zero gradient; Adam's
    moments for its weights stay 0 and its weights do not move.
    """

    def __init__(self, loss: LossModule, optimizer: torch.optim.Optimizer, capacity: int = 50_000,
                 batch_size: int = 32, warmup: int | None = None, target_update: int = 500,
                 train_every: int = 1, seed: int | Tensor = 0):  # fmt: skip
        if min(capacity, batch_size, target_update, train_every) < 1:
            raise ValueError("capacity, batch_size, target_update and train_every must be >= 1")
        self.loss, self.optimizer = loss, optimizer
        self.batch_size = int(batch_size)
        self.warmup = self.batch_size if warmup is None else int(warmup)
        self.memory = AgentReplayStorage(capacity, self.batch_size, seed, stream=STREAM)
        targets = any(name.startswith("target_") for name, _ in loss.named_children())
        self.updater = (HardUpdate(loss, value_network_update_interval=int(target_update))
                        if targets else None)  # fmt: skip
        self.train_every, self.calls, self.updates = int(train_every), 0, 0
        self._writes: Tensor | None = None  # the head's set_values counts at the last copy

    @property
    def stored(self) -> int:
        """Transitions stored so far, all agents together."""
        return 0 if self.memory.count is None else int(self.memory.count.sum())

    def __call__(self, td: TensorDictBase) -> Tensor:
        if hasattr(self.loss, "td_error"):
            delta = self.loss.td_error(td)
        else:
            with torch.no_grad():
                delta = self.loss(td)["td_error"]
        active = td.get("active").to(torch.bool)
        if bool(active.any()):
            self.memory.add(td.detach(), active)
        self.calls += 1
        if self.calls % self.train_every == 0:
            stepped = td.get("stepped", None)
            self._step(None if stepped is None else stepped.to(torch.bool))
        self._copy_written()
        return delta

    def _step(self, stepped: Tensor | None) -> None:
        self.optimizer.zero_grad()
        if self.memory.started:
            ready = self.memory.count >= self.warmup
            if stepped is not None:
                ready = ready & stepped
            batch = self.memory.sample(ready)  # [B, P]
            batch.set("active", batch.get("active").to(torch.bool) & ready)
            self.loss(batch)["loss"].backward()
        params = [p for group in self.optimizer.param_groups for p in group["params"]]
        for param in params:  # no agent warm yet: a step of zeros
            if param.grad is None:
                param.grad = torch.zeros_like(param)
        held = [] if stepped is None or bool(stepped.all()) else [
            (param, param.detach()[~stepped].clone()) for param in params
            if param.ndim and param.shape[0] == stepped.shape[0]]  # fmt: skip
        self.optimizer.step()
        with torch.no_grad():
            for param, rows in held:
                param[~stepped] = rows
        self.updates += 1
        if self.updater is not None:
            self.updater.step()

    def _copy_written(self) -> None:
        """Discovery set a joining option's value: the target copy takes it now, or targets
        would bootstrap from the slot's stale value until the next scheduled copy. Only the
        agents whose head was written (a head counting writes per agent, ``writes [P]``, as
        :class:`~skillchain_torch.modules.MLPQHead`, with parameters stacked ``[P, ...]``);
        a head counting one total has all its targets copied."""
        head = getattr(self.loss, "value_head", None)
        writes = getattr(head, "writes", None)
        if writes is None or self.updater is None:
            return
        if self._writes is None:  # (before the first call no write was copied)
            self._writes = torch.zeros_like(writes)
        changed = writes != self._writes
        if not bool(changed.any()):
            return
        for name, target in self.loss.named_children():
            if name.startswith("target_"):
                source = getattr(self.loss, name[len("target_"):]).data
                if changed.ndim == 0:
                    target.data.copy_(source)
                else:
                    target.data.update_(source.apply(
                        lambda new, old: torch.where(
                            changed.to(new.device).reshape(-1, *[1] * (new.ndim - 1)), new, old),
                        target.data))  # fmt: skip
        self._writes = writes.clone()

    def state_dict(self) -> dict:
        return {"memory": self.memory.state_dict(), "optimizer": self.optimizer.state_dict(),
                "updates": self.updates, "calls": self.calls, "writes": self._writes,
                "targets": self.loss.state_dict(),
                "counter": getattr(self.updater, "counter", 0)}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        device = next(iter(self.loss.parameters()), torch.zeros(())).device
        self.memory.load_state_dict(saved_memory(state), device=device)
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates, self.calls = int(state["updates"]), int(state["calls"])
        writes = state["writes"]
        self._writes = writes if writes is None else writes.to(device)
        self.loss.load_state_dict(state["targets"])
        if self.updater is not None:
            self.updater.counter = int(state["counter"])
