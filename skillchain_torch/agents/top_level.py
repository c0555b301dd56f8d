"""The top level of the hierarchical agent: its choice among primitives and options, and how
it learns (paper section 2: SMDP Sarsa over ``A + K`` decisions).

A mixin of :class:`~skillchain_torch.agents.HierarchicalAgent`, which owns the state it reads
(``q_head``, ``features``, ``bank``, ``update``/``loss``/``optimizer``, ``epsilon``); kept
apart so the agent's step reads in one file and the top level's rules in another.

Example:
    >>> from skillchain_torch.agents import HierarchicalAgent
    >>> from skillchain_torch.options import OptionBank
    >>> agent = HierarchicalAgent(OptionBank.build(population=1, slots=2, order=1), order=1)
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=torch.float64)
    >>> agent.top_level_available(obs).tolist()   # five primitives; no option executable yet
    [[True, True, True, True, True, False, False]]
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torch import Tensor

from skillchain_torch.backends import hierarchical as backend
from skillchain_torch.features import FourierBasis
from skillchain_torch.options import FourierOptionQHead
from skillchain_torch.policies import epsilon_greedy

__all__ = ["TopLevel", "shared_fourier_columns"]


def shared_fourier_columns(basis: FourierBasis, q_head) -> Tensor | None:
    """Where the option heads' Fourier features sit among ``basis``'s, or ``None``.

    A :class:`~skillchain_torch.options.FourierOptionQHead` of order ``o <= basis.order`` over
    the same observation has coefficient vectors ``c in {0..o}^4``, a subset of ``basis``'s,
    and :class:`FourierBasis` computes each ``cos(pi c . s)`` the same way whatever the order
    (``c . s`` summed over the dims in order from the same products ``s_j * c_j``, then an
    elementwise cosine), so ``q_head.encode(s)`` equals ``basis(s)[:, columns]`` bit for bit.

    Example:
        >>> from skillchain_torch.options import FourierOptionQHead
        >>> columns = shared_fourier_columns(FourierBasis(4, 4), FourierOptionQHead(1, 1, order=3))
        >>> columns.shape, columns[:3].tolist()
        (torch.Size([256]), [0, 1, 2])
    """
    inner = getattr(q_head, "basis", None)
    if type(q_head) is not FourierOptionQHead:  # a subclass may encode its own way
        return None
    if (not isinstance(inner, FourierBasis) or inner.dim != basis.dim
            or inner.order > basis.order or inner.coefficients.dtype != basis.coefficients.dtype
            or inner.coefficients.device != basis.coefficients.device):  # fmt: skip
        return None
    radix = basis.order + 1
    places = radix ** torch.arange(basis.dim - 1, -1, -1, device=inner.coefficients.device)
    return (inner.coefficients.to(torch.int64) * places).sum(-1)


class TopLevel:
    """The top level's choice (:meth:`_choose`) and learning (:meth:`learn`)."""

    def top_level_available(self, obs: Tensor, contains: Tensor | None = None) -> Tensor:
        """``[P, 5 + K]``: the primitives (always) and the available options at ``obs``."""
        options = self.bank.available(obs, contains)
        primitives = torch.ones(self.population, self.num_primitives, dtype=torch.bool,
                                device=options.device)
        return torch.cat([primitives, options], dim=-1)

    def _encode(self, obs: Tensor, index: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """``(phi(s), option code of s)``: the top-level features and the option heads' code
        (of the rows ``index`` of ``obs [P, 4]`` only, when given: ``[len(index), .]``).

        When the option heads use a Fourier basis of the same observation and no higher order
        (the paper: order 3 under order 4), their features are columns of the top level's,
        computed with the same arithmetic (see :func:`shared_fourier_columns`), so they are
        picked rather than computed again."""
        phi = self.features(obs if index is None else obs[index])
        if self._code_columns is not None:
            return phi, phi[:, self._code_columns]
        code = self.bank.q_head.encode(obs)  # a head's code may need every row (its checks)
        return phi, code if index is None else code[index]

    def _choose(self, obs: Tensor, phi: Tensor, contains: Tensor, uniforms: Tensor,
                rows: Tensor | None = None) -> tuple[Tensor, Tensor]:  # fmt: skip
        """Top-level epsilon-greedy decision at ``obs``; ``(phi, decision)``.

        Only the agents in ``rows [P]`` (default all) need a decision: an executing option that
        goes on needs none, and the 5 + K values are the top level's largest cost. Other rows'
        decisions are meaningless. ``phi`` and ``Q(obs, .)`` stay in ``last_phi`` and
        ``last_q`` for subclasses (``last_q`` valid on ``rows`` for the available decisions,
        0 for the others). ``phi``: ``features(obs)``, from :meth:`_encode`."""
        available = self.top_level_available(obs, contains)
        rows = torch.ones_like(self.active) if rows is None else rows
        if self.native:
            q, decision = backend.choose(self.q_head.weight, phi, available, rows,
                                         self.num_primitives, uniforms, self.epsilon)  # fmt: skip
            self.last_phi, self.last_q, self.last_available = phi, q, available
            return phi, decision
        # Value only what can be chosen: the primitives, and the few options whose initiation
        # set holds the state (each value is the same row sum as a full forward).
        if self.closed_form:  # (a buffer: no graph; the hot path skips the context)
            q = self.q_head.forward_mask(phi, available & rows[:, None], dense=self.num_primitives)
        else:  # a head of the user's own: acting values are never differentiated
            with torch.no_grad():
                q = self.q_head.forward_mask(phi, available & rows[:, None],
                                             dense=self.num_primitives)  # fmt: skip
        self.last_phi, self.last_q, self.last_available = phi, q, available
        return phi, epsilon_greedy(q, available, self.epsilon, uniforms,
                                   check=False)  # primitives are always available

    def learn(self, phi: Tensor, decision: Tensor, ret: Tensor, duration: Tensor,
              next_value: Tensor, terminated: Tensor, active: Tensor,
              **next_state: Tensor) -> Tensor:  # fmt: skip
        """One SMDP Sarsa step of the top-level head toward ``ret + gamma^k next_value``
        for the ``active`` agents; their TD errors ``[P]``. The built-in linear head steps in
        closed form (:class:`SarsaUpdate`); any other by its loss and optimizer, or by the
        agent's ``top_learner`` (which also reads ``next_state``: ``next_phi``,
        ``next_decision``, ``next_available``, and ``stepped``: the agents still running)."""
        if self.closed_form:
            return self.update(self.q_head, phi, decision, ret, duration, phi, decision,
                               terminated, active=active, next_value=next_value)
        with torch.enable_grad():
            return self._loss_step(phi, decision, ret, duration, next_value, terminated, active,
                                   next_state)  # fmt: skip

    def _loss_step(self, phi, decision, ret, duration, next_value, terminated, active,
                   next_state=None) -> Tensor:  # fmt: skip
        extra = next_state if self.top_learner is not None and next_state else {}
        td = TensorDict(phi=phi, decision=decision, decision_return=ret, duration=duration,
                        next_value=next_value, terminated=terminated, active=active, **extra,
                        batch_size=[self.population])  # fmt: skip
        if self.top_learner is not None:
            return self.top_learner(td)
        self.optimizer.zero_grad()
        out = self.loss(td)
        out["loss"].backward()
        self.optimizer.step()
        return out["td_error"]

