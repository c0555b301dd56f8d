"""The hierarchical agent's step in one compiled pass: chosen once, when the agent is built.

:class:`CompiledStep` is what :func:`~.select.hierarchical_step` hands an agent whose pieces
are exactly the built-in ones (a Fourier option head, the linear top level over a Fourier
basis), on the CPU in float64, where :mod:`.hierarchical`'s kernels are built. The agent binds
its three calls once (the top level's values and choice, the executing options' actions, and
the rest of a transition after the memberships, targets and uniforms of ``s'``), so its own
file reads as the torch path alone. Each call marshals the agent's declared state
(:class:`~skillchain_torch.agents.step_state.StepState`, its weights and settings) into the
kernels and back; the sums run in the kernels' own order (equal to the torch path to rounding,
each agent's numbers its own).

Example:
    >>> from skillchain_torch.agents import SkillChainingAgent
    >>> agent = SkillChainingAgent.build(2, order=1)
    >>> agent.native == AVAILABLE, isinstance(agent.kernel, CompiledStep) == AVAILABLE
    (True, True)
"""

from __future__ import annotations

from torch import Tensor

from skillchain_torch.backends import hierarchical as kernels

__all__ = ["AVAILABLE", "CompiledStep"]

AVAILABLE = kernels.AVAILABLE


class CompiledStep:
    """The compiled calls of a :class:`~skillchain_torch.agents.HierarchicalAgent` (see the
    module docstring); stateless: every call reads the agent it is given and returns what it
    computed, which the agent adopts (no attribute of the agent is written here)."""

    @staticmethod
    def decide(agent, phi: Tensor, available: Tensor, rows: Tensor,
               uniforms: Tensor) -> tuple[Tensor, Tensor]:  # fmt: skip
        """``(Q [P, D], decision [P])``: the top level's values and epsilon-greedy choice."""
        return kernels.choose(agent.q_head.weight, phi, available, rows, agent.num_primitives,
                              uniforms, agent.epsilon)  # fmt: skip

    @staticmethod
    def actions(agent, rows: Tensor, uniforms: Tensor) -> Tensor:
        """``[P]``: the primitive decisions, or the executing options' epsilon-greedy actions."""
        return kernels.act(agent.bank.q_head.weight, agent.option_code, rows, agent.decision,
                           agent.option, uniforms, agent.option_epsilon,
                           agent.action.clone())  # fmt: skip

    @staticmethod
    def rules(agent) -> kernels.StepRules:
        """The settings the compiled step follows, as the agent holds them now."""
        return kernels.StepRules(
            epsilon=agent.epsilon, option_epsilon=agent.option_epsilon, gamma=agent.gamma,
            max_option_steps=agent.max_option_steps, option_alpha=agent.bank.q_head.alpha,
            completion_reward=float(agent.option_update.completion_reward),
            failure_bootstrap_primitives=agent.failure_bootstrap == "primitives",
            intra_option_primitives=agent.intra_option_primitives,
            intra_option_primitive_target=agent.intra_option_target == "primitives",
            interruption=agent.interruption, leave_from=agent.leave_from)  # fmt: skip

    @classmethod
    def transition(cls, agent, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                   truncated: Tensor, stepped: Tensor, contains_next: Tensor, reached: Tensor,
                   uniforms: Tensor, own_next: Tensor) -> tuple:  # fmt: skip
        """The rest of ``HierarchicalAgent.transition`` in one pass. It writes no attribute of
        the agent (the kernel updates the weights and three state arrays in place, as the torch
        path does): it returns ``(state, phi, q, value, started, info)``, the new
        :class:`~skillchain_torch.agents.step_state.StepState`, the top level's features and
        values at s' (``value``: Q(s', d) of the decision in force, where the agent wants it),
        the rows that started an option, and the same monitoring dict as the torch path, for
        the agent to adopt. Where the option heads' features are among the top level's, the
        kernel picks them from ``phi`` itself instead of a second basis."""
        phi = agent.features(next_obs)
        columns = agent._code_columns
        code = agent.bank.q_head.encode(next_obs) if columns is None else None
        at_next = kernels.AtNext(next_obs, reward, terminated, truncated, stepped,
                                 contains_next, reached, uniforms, phi, code, columns,
                                 own=own_next)  # fmt: skip
        learned = kernels.Learned(agent.q_head.weight, agent.bank.q_head.weight,
                                  agent.update.step_size, agent.bank.status)  # fmt: skip
        before = agent.step_state
        state, out = kernels.transition(before, learned, at_next, cls.rules(agent),
                                        want_value=agent.WANTS_VALUE)  # fmt: skip
        info = {"decision_ended": out.decision_ended, "duration": out.duration,
                "decision_return": out.decision_return, "option_delta": out.option_delta,
                "smdp_delta": out.smdp_delta, "decision": before.decision,
                "option": before.option, "reached": reached}  # fmt: skip
        return state, phi, out.q, out.value, out.started, info
