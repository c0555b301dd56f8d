"""The episode protocol every agent of a trainer follows (rows = active agents, ascending id).

``begin(obs)``, ``observe(obs, reward)``, ``observe_ends(obs, reward, terminated, truncated,
restart_rows, start_obs)``, ``compact(keep)``, ``actions``, ``index``, ``flush()``: a mixin of
:class:`~skillchain_torch.agents.HierarchicalAgent` that maps the trainer's compact rows onto
the agent's P rows and calls its :meth:`transition` (the flat agent,
:class:`~skillchain_torch.agents.FlatSarsaAgent`, keeps the same protocol).

Example:
    >>> from skillchain_torch.agents import HierarchicalAgent
    >>> from skillchain_torch.options import OptionBank
    >>> agent = HierarchicalAgent(OptionBank.build(population=2, slots=2, order=1), order=1)
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
    >>> agent.begin(obs).shape, agent.index.tolist()
    (torch.Size([2]), [0, 1])
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends.native import check_same_kernels
from skillchain_torch.objectives.option_replay import OptionReplay

__all__ = ["EpisodeProtocol"]


class EpisodeProtocol:
    """The trainer's side of an agent: compact rows in, actions out."""

    def all_active(self) -> bool:
        """Every agent is active: rows are agents (a check without a call into torch)."""
        return self._index.numel() == self.population

    def all_stepped(self, stepped: Tensor) -> bool:
        """``stepped`` is the agent's own ``active`` mask with every agent active (what
        :meth:`observe` passes): per-row masking by it changes nothing, so it can be skipped."""
        return stepped is self.active and self.all_active()

    # ------------------------------------------------------------------ protocol
    def _full(self, rows_value: Tensor, fill: Tensor) -> Tensor:
        if self.all_active():  # rows are agents
            return rows_value if rows_value.dtype == fill.dtype else rows_value.to(fill.dtype)
        out = fill.clone()
        out[self._index] = rows_value if rows_value.dtype == out.dtype else rows_value.to(out.dtype)
        return out

    def begin(self, obs: Tensor) -> Tensor:
        """First decisions of every active agent at its start observation ``[n, 4]``."""
        self._start_decisions(self._full(obs, self.obs), self.active.clone())
        return self.actions

    def observe(self, obs: Tensor, reward: Tensor) -> Tensor:
        """Learn from a step in which no episode ended; the next actions ``[n]``."""
        none = torch.zeros_like(self.active)
        self.transition(self._full(obs, self.obs), self._full(reward, self.decision_return),
                        none, none, self.active)
        return self.actions

    def observe_ends(self, obs: Tensor, reward: Tensor, terminated: Tensor, truncated: Tensor,
                     restart_rows: Tensor, start_obs: Tensor | None) -> Tensor:
        """Like :meth:`observe` when some episodes ended (see ``FlatSarsaAgent``): terminal
        updates do not bootstrap, truncated ones do; rows in ``restart_rows`` then decide at
        ``start_obs``."""
        none = torch.zeros_like(self.active)
        terminated, truncated = self._full(terminated, none), self._full(truncated, none)
        self.transition(self._full(obs, self.obs), self._full(reward, self.decision_return),
                        terminated, truncated, self.active)
        self.episodes_ended(self.active & (terminated | truncated))
        if restart_rows.numel() > 0:
            restart = torch.zeros_like(self.active)
            restart[self._index[restart_rows]] = True
            start = self.obs.clone()
            start[self._index[restart_rows]] = start_obs.to(start.dtype)
            self._start_decisions(start, restart)
        return self.actions

    def episodes_ended(self, rows: Tensor) -> None:
        """Agents ``rows [P]`` just ended an episode (before any restart); nothing to do here,
        skill chaining runs its per-episode rules."""

    def compact(self, keep: Tensor) -> None:
        """Keep the active rows where ``keep [n]``; the others stop for good."""
        self._index = self._index[keep]
        active = torch.zeros_like(self.active)
        active[self._index] = True
        self.active = active

    @property
    def index(self) -> Tensor:
        """Ids of the active agents, ascending ``[n]``."""
        return self._index

    @property
    def actions(self) -> Tensor:
        """The primitive action of each active row ``[n]``."""
        if self.all_active():  # (action is replaced, never written)
            return self.action
        return self.action[self._index]

    @property
    def decisions(self) -> Tensor:
        """The top-level decision in force for each active row ``[n]`` (5 + k: option k)."""
        return self.decision[self._index]

    @property
    def options(self) -> Tensor:
        """The executing option slot of each active row ``[n]`` (-1: none)."""
        return self.option[self._index]

    def flush(self) -> None:
        """Nothing to write back: the state is held for all agents."""

    # ------------------------------------------------------------------ state
    _EPISODE = ("obs", "contains", "own_contains", "decision", "option", "decision_return",
                "duration", "active")

    def state_dict(self, *args, **kwargs):
        """Top-level weights, options, streams, and every agent's episode state.

        Laid out like ``FlatSarsaAgent``'s (``q_head``, ``rng``, ``index``, ``action``,
        ``phi``: the features of the state where the decision in force was taken), plus
        ``bank`` and ``episode`` (the per-agent option state).
        """
        return {
            "q_head": self.q_head.state_dict(),
            "rng": self.rng.state_dict(),
            "index": self._index.clone(),
            "action": self.action.clone(),
            "phi": self.decision_phi.clone(),
            "bank": self.bank.state_dict(),
            "episode": {name: getattr(self, name).clone() for name in self._EPISODE},
            "native": self.native,
            **({} if self.optimizer is None else {"optimizer": self.optimizer.state_dict()}),
            **({"top_learner": self.top_learner.state_dict()}
               if hasattr(getattr(self, "top_learner", None), "state_dict") else {}),
            **({"option_replay": self.bank.q_head.replay.state_dict()}
               if getattr(self.bank.q_head, "replay", None) is not None else {}),
        }

    def load_state_dict(self, state, strict: bool = True, assign: bool = False):
        device = self.obs.device
        check_same_kernels(state, self.native)
        self.q_head.load_state_dict(state["q_head"])
        if self.optimizer is not None and "optimizer" in state:
            self.optimizer.load_state_dict(state["optimizer"])
        if "top_learner" in state:
            self.top_learner.load_state_dict(state["top_learner"])
        if "option_replay" in state:
            replay = self.bank.q_head.replay  # (the built-in one moves to the bank's device)
            if isinstance(replay, OptionReplay):
                replay.load_state_dict(state["option_replay"], device=self.bank.status.device)
            else:
                replay.load_state_dict(state["option_replay"])
        self.bank.load_state_dict(state["bank"])
        self.rng.load_state_dict(state["rng"])
        self.rng.to(device)
        self._index = state["index"].to(device)
        self.action = state["action"].to(device).clone()
        self.decision_phi = state["phi"].to(device).clone()
        episode = state["episode"]
        if "own_contains" not in episode:  # saved before the own sets were kept (issue 30):
            episode = {**episode, "own_contains": episode["contains"]}  # what it learned by
        for name in self._EPISODE:
            setattr(self, name, episode[name].to(device).clone())
        phi, self.option_code = self._encode(self.obs)  # pure functions of s
        if self.intra_option_primitives:
            self.state_phi = phi
