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

from skillchain_torch.objectives.agent_storage import AgentReplayStorage, saved_memory

__all__ = ["OptionReplay"]

STREAM = 0x0B8  # the option heads' replay draws (a CounterRNG stream of its own)


class OptionReplay:
    """Store each transition with its update mask; step the head on sampled minibatches.

    Args:
        capacity: transitions kept per agent; batch_size: B transitions per agent per
            minibatch.
        train_every: one minibatch step per this many calls (population steps, which are the
            agent's own steps).
        warmup: an agent's transitions stored before it learns (default ``batch_size``).
        target_update: an agent's minibatch steps between copies of its target parameters
            (which value ``max_a Q(s', a)``).
        seed: int (agent p samples with ``seed + p``) or ``LongTensor [P]``.

    **Per agent.** Agent p stores the transitions in which some option of its own learns (its
    mask row is not all False), in a ring of its own, sampled by a stream of its own
    (:class:`~skillchain_torch.objectives.agent_storage.AgentReplayStorage`); it learns at every
    ``train_every``-th call once it holds ``warmup`` transitions, and its target is copied on
    its own update count and whenever one of its slots is reset. The head steps by plain SGD
    (no optimizer state), so an agent masked out of a step does not move: its run depends on
    its seed alone, whatever the rest of the population does.
    """

    def __init__(self, capacity: int = 50_000, batch_size: int = 32, train_every: int = 4,
                 warmup: int | None = None, target_update: int = 250,
                 seed: int | Tensor = 0):  # fmt: skip
        if min(capacity, batch_size, train_every, target_update) < 1:
            raise ValueError("capacity, batch_size, train_every and target_update must be >= 1")
        self.batch_size, self.train_every = int(batch_size), int(train_every)
        self.warmup = self.batch_size if warmup is None else int(warmup)
        self.target_update = int(target_update)
        self.memory = AgentReplayStorage(capacity, self.batch_size, seed, stream=STREAM)
        self.calls = 0
        self.updates: Tensor | None = None  # [P] minibatch steps each agent has taken
        self.target: list[tuple[Tensor, Tensor]] | None = None
        self._epochs: Tensor | None = None  # [P] each agent's slot resets at its last copy

    @property
    def stored(self) -> int:
        """Transitions stored so far, all agents together."""
        return 0 if self.memory.count is None else int(self.memory.count.sum())

    def __call__(self, head, obs: Tensor, action: Tensor, reward: Tensor, next_obs: Tensor,
                 terminated: Tensor, reached: Tensor, mask: Tensor, gamma: float,
                 completion_reward, alive: Tensor | None = None) -> Tensor:  # fmt: skip
        """Store the transition (``[P]`` rows, ``mask [P, K]``); maybe step the agents in
        ``alive [P]`` (default all: an agent that finished its episodes stops learning);
        ``delta [P, K]`` of this transition under the current parameters (0 off ``mask``)."""
        from skillchain_torch.objectives.q_learning import option_td_target

        rows = mask.any(-1)
        if not bool(rows.any()):  # no option learns here: nothing to value or store
            delta = torch.zeros(mask.shape, dtype=torch.float64, device=mask.device)
        else:
            with torch.no_grad():
                target = option_td_target(reward, head(next_obs).amax(-1), reached, terminated,
                                          gamma, completion_reward)  # fmt: skip
                q_sa = head(obs).gather(2, action.to(torch.int64)[:, None, None].expand(
                    -1, head.slots, 1))[..., 0]  # fmt: skip
                delta = torch.where(mask, target - q_sa, torch.zeros_like(q_sa))
            P = head.population
            item = TensorDict(obs=obs, action=action.to(torch.int64), reward=reward.reshape(P),
                              next_obs=next_obs, terminated=terminated.reshape(P).to(torch.bool),
                              reached=reached, mask=mask, epoch=head.slot_epoch.clone(),
                              batch_size=[P])  # fmt: skip
            self.memory.add(item, rows)
        self.calls += 1
        if self.calls % self.train_every == 0 and self.memory.started:
            ready = self.memory.count >= self.warmup
            if alive is not None:
                ready = ready & alive.to(device=ready.device, dtype=torch.bool)
            if bool(ready.any()):
                self._learn(head, gamma, completion_reward, ready)
        return delta

    def _copy_targets(self, head, ready: Tensor) -> None:
        """Agent p's target takes its online weights every ``target_update`` of its own steps,
        and whenever one of its slots was reset (a new option took it: copy the fresh net)."""
        epochs = head.slot_epoch.sum(-1)
        if self.target is None:
            self.target = [(w.detach().clone(), b.detach().clone()) for w, b in head._layers()]
            self.updates = torch.zeros_like(epochs)
            self._epochs = epochs.clone()
            return
        copy = (ready & (self.updates % self.target_update == 0)) | (epochs != self._epochs)
        if not bool(copy.any()):
            return
        self._epochs = torch.where(copy, epochs, self._epochs)
        for (tw, tb), (w, b) in zip(self.target, head._layers()):
            tw.copy_(torch.where(copy.reshape(-1, *[1] * (w.ndim - 1)), w.detach(), tw))
            tb.copy_(torch.where(copy.reshape(-1, *[1] * (b.ndim - 1)), b.detach(), tb))

    def _learn(self, head, gamma: float, completion_reward, ready: Tensor | None = None) -> None:
        from skillchain_torch.objectives.q_learning import option_td_target

        P, K = head.population, head.slots
        if ready is None:
            ready = self.memory.count >= 1
        self._copy_targets(head, ready)
        batch = self.memory.sample(ready)  # [B, P]
        B = batch.shape[0]
        # A slot a new option took since the transition was stored learns nothing from it, and
        # an agent not yet warm learns nothing at all.
        mask = batch["mask"] & (batch["epoch"] == head.slot_epoch) & ready[:, None]
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
        self.updates = self.updates + ready.to(self.updates)

    def state_dict(self) -> dict:
        return {"memory": self.memory.state_dict(), "calls": self.calls,
                "updates": self.updates, "target": self.target, "epochs": self._epochs}

    def load_state_dict(self, state: dict, device: torch.device | str | None = None) -> None:
        """Restore :meth:`state_dict`'s state, on ``device`` (default: where it was saved)."""
        self.memory.load_state_dict(saved_memory(state), device=device)

        def moved(t):
            return t if t is None or device is None else t.to(device)

        self.calls, self.updates = int(state["calls"]), moved(state["updates"])
        self._epochs = moved(state["epochs"])
        self.target = (None if state["target"] is None else
                       [(moved(w), moved(b)) for w, b in state["target"]])  # fmt: skip
