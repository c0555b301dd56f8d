"""Replay for the option heads: intra-option Q-learning from sampled past transitions.

The paper's option heads learn from each transition once, as it happens (section 5.1). A neural
head learns better from a replayed minibatch with a target network, as DQN does. Which option
learns from which transition is the paper's rule (:func:`option_update_mask`: the executing
option on-policy wherever it goes, every other option off-policy only from states in its own
initiation set), decided when the transition is stored and kept with it, so the rule is
expressed by what is sampled: a slot learns from a replayed transition only where the mask
held. A slot that a new option has taken since (its head was reset) does not learn from its
predecessor's transitions.

Attach one to a head that can take a minibatch step (``head.step(obs [B, P, D], action [B, P],
target [B, P, K], mask [B, P, K])``, as :class:`~skillchain_torch.options.MLPOptionQHead`):
``head.replay = OptionReplay(...)``; :class:`IntraOptionQLearning` then hands it each
transition instead of stepping the head once.

Example:
    >>> import torch
    >>> from skillchain_torch.objectives import IntraOptionQLearning
    >>> from skillchain_torch.options import MLPOptionQHead
    >>> head = MLPOptionQHead(population=2, slots=1, hidden=16, lr=0.05)
    >>> head.replay = OptionReplay(batch_size=8, train_every=1, target_update=20)
    >>> learn = IntraOptionQLearning(gamma=1.0, completion_reward=10_000.0)
    >>> s = torch.full((2, 4), 0.5, dtype=torch.float64)
    >>> for _ in range(300):     # one step from s reaches the target: Q = -1 + 10,000
    ...     _ = learn(head, s, torch.tensor([0, 0]), -torch.ones(2, dtype=torch.float64), s,
    ...               torch.tensor([False, False]), torch.ones(2, 1, dtype=torch.bool),
    ...               torch.ones(2, 1, dtype=torch.bool))
    >>> [round(v, -2) for v in head(s)[:, 0, 0].tolist()]
    [10000.0, 10000.0]
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torch import Tensor

from skillchain_torch.objectives.replay import seeded_buffer, store

__all__ = ["OptionReplay"]


class OptionReplay:
    """Store each transition with its update mask; step the head on sampled minibatches.

    Args:
        capacity: population steps kept; batch_size: B population steps per minibatch.
        train_every: one minibatch step per this many stored steps.
        warmup: steps stored before the first (default ``batch_size``).
        target_update: minibatch steps between copies of the target parameters that value
            ``max_a Q(s', a)``.
        seed: of the sampling generator (the global RNG is never touched).
    """

    def __init__(self, capacity: int = 50_000, batch_size: int = 32, train_every: int = 4,
                 warmup: int | None = None, target_update: int = 250, seed: int = 0):  # fmt: skip
        if min(capacity, batch_size, train_every, target_update) < 1:
            raise ValueError("capacity, batch_size, train_every and target_update must be >= 1")
        self.batch_size, self.train_every = int(batch_size), int(train_every)
        self.warmup = self.batch_size if warmup is None else int(warmup)
        self.target_update = int(target_update)
        self.buffer, self.generator = seeded_buffer(capacity, self.batch_size, seed)
        self.stored = self.updates = 0
        self.target: list[tuple[Tensor, Tensor]] | None = None
        self._epochs = -1  # the heads' reset count at the last target copy

    def __call__(self, head, obs: Tensor, action: Tensor, reward: Tensor, next_obs: Tensor,
                 terminated: Tensor, reached: Tensor, mask: Tensor, gamma: float,
                 completion_reward) -> Tensor:  # fmt: skip
        """Store the transition (``[P]`` rows, ``mask [P, K]``); maybe step; ``delta [P, K]``
        of this transition under the current parameters (0 off ``mask``)."""
        from skillchain_torch.objectives.q_learning import option_td_target

        with torch.no_grad():
            target = option_td_target(reward, head(next_obs).amax(-1), reached, terminated,
                                      gamma, completion_reward)  # fmt: skip
            q_sa = head(obs).gather(2, action.to(torch.int64)[:, None, None].expand(
                -1, head.slots, 1))[..., 0]  # fmt: skip
            delta = torch.where(mask, target - q_sa, torch.zeros_like(q_sa))
        if not bool(mask.any()):
            return delta
        P = head.population
        item = TensorDict(obs=obs, action=action.to(torch.int64), reward=reward.reshape(P),
                          next_obs=next_obs, terminated=terminated.reshape(P).to(torch.bool),
                          reached=reached, mask=mask, epoch=head.slot_epoch.clone(),
                          batch_size=[P])  # fmt: skip
        store(self.buffer, item)
        self.stored += 1
        if len(self.buffer) >= self.warmup and self.stored % self.train_every == 0:
            self._learn(head, gamma, completion_reward)
        return delta

    def _learn(self, head, gamma: float, completion_reward) -> None:
        from skillchain_torch.objectives.q_learning import option_td_target

        epochs = int(head.slot_epoch.sum())  # a new option took a slot: copy its fresh net
        if (self.target is None or self.updates % self.target_update == 0
                or epochs != self._epochs):  # fmt: skip
            self._epochs = epochs
            self.target = [(w.detach().clone(), b.detach().clone()) for w, b in head._layers()]
        batch = self.buffer.sample()  # [B, P]
        B, P, K = batch.shape[0], head.population, head.slots
        # A slot a new option took since the transition was stored learns nothing from it.
        mask = batch["mask"] & (batch["epoch"] == head.slot_epoch)
        with torch.no_grad():
            next_max = head._values(batch["next_obs"], self.target).amax(-1)  # [B, P, K]
            c = torch.as_tensor(completion_reward, dtype=next_max.dtype, device=next_max.device)
            c = c.expand(B, P, K).reshape(B * P, K) if c.ndim else c
            target = option_td_target(batch["reward"].reshape(B * P),
                                      next_max.reshape(B * P, K),
                                      batch["reached"].reshape(B * P, K),
                                      batch["terminated"].reshape(B * P), gamma,
                                      c).reshape(B, P, K)  # fmt: skip
        head.step(batch["obs"], batch["action"], target, mask)
        self.updates += 1

    def state_dict(self) -> dict:
        return {"buffer": self.buffer.state_dict(), "generator": self.generator.get_state(),
                "stored": self.stored, "updates": self.updates, "target": self.target,
                "epochs": self._epochs}

    def load_state_dict(self, state: dict) -> None:
        self.buffer.load_state_dict(state["buffer"])
        self.generator.set_state(state["generator"])
        self.stored, self.updates = int(state["stored"]), int(state["updates"])
        self.target, self._epochs = state["target"], int(state["epochs"])
