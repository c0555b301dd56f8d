"""The hierarchical agent's compiled step: what it hands the backend, and what it keeps.

A mixin of :class:`~skillchain_torch.agents.HierarchicalAgent` (``native=True``). Its
:meth:`~CompiledStep._compiled_transition` gathers the agent's declared pieces (its
:class:`~skillchain_torch.agents.step_state.StepState`, the weights the step learns, its
settings) and makes one call into :func:`skillchain_torch.backends.hierarchical.transition`,
which returns the state at ``s'``; the agent then keeps that state and the values its
subclasses read (``last_phi``, ``last_q``, ``last_value``). The rules themselves are the torch
path's, in :meth:`HierarchicalAgent.transition`.

Example:
    >>> import torch
    >>> from skillchain_torch.agents import HierarchicalAgent
    >>> from skillchain_torch.options import OptionBank
    >>> agent = HierarchicalAgent(OptionBank.build(population=1, slots=2, order=1), order=1,
    ...                           native=False)
    >>> agent.step_rules().max_option_steps
    250
"""

from __future__ import annotations

from torch import Tensor

from skillchain_torch.backends import hierarchical as backend

__all__ = ["CompiledStep"]


class CompiledStep:
    """The agent's side of :mod:`skillchain_torch.backends.hierarchical`."""

    def step_rules(self) -> backend.StepRules:
        """The settings the compiled step follows, as the agent holds them now."""
        return backend.StepRules(
            epsilon=self.epsilon, option_epsilon=self.option_epsilon, gamma=self.gamma,
            max_option_steps=self.max_option_steps, option_alpha=self.bank.q_head.alpha,
            completion_reward=float(self.option_update.completion_reward),
            failure_bootstrap_primitives=self.failure_bootstrap == "primitives",
            intra_option_primitives=self.intra_option_primitives,
            intra_option_primitive_target=self.intra_option_target == "primitives",
            interruption=self.interruption, leave_from=self.leave_from)  # fmt: skip

    def _encode_next(self, next_obs: Tensor) -> tuple[Tensor, Tensor | None, Tensor | None]:
        """``(phi(s'), the option heads' code of s' or None, the columns of phi it is picked
        from or None)``: where the code's features are among the top level's
        (:func:`~skillchain_torch.agents.top_level.shared_fourier_columns`), the step picks
        them itself instead of a second basis."""
        phi = self.features(next_obs)
        columns = self._code_columns
        return phi, self.bank.q_head.encode(next_obs) if columns is None else None, columns

    def _compiled_transition(self, at_next: backend.AtNext) -> dict[str, Tensor]:
        """The rest of :meth:`transition` after the memberships, targets and uniforms of
        ``s'``, in one compiled pass; the same monitoring dict."""
        learned = backend.Learned(self.q_head.weight, self.bank.q_head.weight,
                                  self.update.step_size, self.bank.status)  # fmt: skip
        before = self.step_state
        self.step_state, out = backend.transition(before, learned, at_next, self.step_rules(),
                                                  want_value=self.WANTS_VALUE)  # fmt: skip
        self.last_phi, self.last_q, self.last_value = at_next.phi, out.q, out.value
        self._options_starting(out.started)
        return {"decision_ended": out.decision_ended, "duration": out.duration,
                "decision_return": out.decision_return, "option_delta": out.option_delta,
                "smdp_delta": out.smdp_delta, "decision": before.decision,
                "option": before.option, "reached": at_next.reached}  # fmt: skip
