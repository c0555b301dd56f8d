"""Gestation and the initial value of a new option (paper section 5.1).

"A newly created option was first allowed a gestation period of 10 episodes where it could not
be executed and its policy was updated using only off-policy learning. After its gestation
period, the option was added to the agent's action repertoire [...] We therefore sampled the Q
values of transitions that triggered the option's target event during its gestation, and
initialized Q(s, o) to the maximum of these values."

* An option created during episode ``e`` gestates through the rest of ``e`` and the ten whole
  episodes after it: at the end of episode ``e + gestation`` it becomes LEARNING (executable).
* The samples are the top-level ``Q(s, d)`` of the decision ``d`` in force at ``s`` on each
  transition ``s -> s'`` that triggered the option's target event, the creating transition
  included (so there is always at least one).
* ``Q(s, o)`` is linear in Fourier features whose first feature is the constant 1
  (coefficient vector 0), so "initialised to a value" means that weight set to it and the
  others to 0: ``Q(s, o) = value`` everywhere.

Two starts the paper does not have, each a parameter of
:class:`~skillchain_torch.discovery.SkillChaining` (``results/screening/README.md`` measures
them):

* ``policy_start="top-level"``: the option's policy starts as the agent's own. Its Q-head is the
  least-squares fit, in its order-3 basis, of the agent's order-4 primitive values
  (:func:`value_projection`, :func:`initialise_option_policies`), as deep skill chaining copies
  the global agent's weights into a new option. Its first executions then head where the agent
  heads, instead of where zero weights and ten episodes of off-policy updates point.
* ``value_start="agent"``: ``Q(s, o)`` starts as the agent's own state value ``max_a Q(s, a)``
  (fitted in its basis, :class:`StateValueFit`) plus a bonus, so the option is tried where it
  is believed about as good as the primitives, not everywhere at the best value seen at its
  target.

With neural heads the two starts are the same fits in the written head's last layer, on a grid
of states (:func:`fitted_starts`, each head's ``fit_values``).

Example:
    >>> import torch
    >>> from skillchain_torch.modules import LinearQHead
    >>> head = LinearQHead(num_features=3, num_decisions=5 + 2, population=1)
    >>> initialise_option_values(head, torch.tensor([[False, True]]),
    ...                          torch.tensor([[0.0, 7.5]], dtype=torch.float64))
    >>> head(torch.tensor([[1.0, 0.3, -0.2]], dtype=torch.float64)).tolist()
    [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 7.5]]
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from skillchain_torch.features import FourierBasis
from skillchain_torch.invariant import rowwise_dot
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import OptionBank, OptionStatus

__all__ = ["GESTATION_EPISODES", "POLICY_STARTS", "VALUE_STARTS", "StateValueFit", "box_grid",
           "cached_projection", "fit_grid", "fitted_starts", "grid_values", "gestation_over",
           "initialise_option_policies",
           "initialise_option_values", "state_value_fit", "value_projection"]

GESTATION_EPISODES = 10
NUM_PRIMITIVES = 5
# How an option's policy starts when it joins: "zero" (the paper is silent; whatever gestation's
# off-policy updates made of zero weights) or "top-level" (the agent's own primitive values
# projected onto the option's basis, as deep skill chaining copies the global agent's weights),
# or "top-level-shifted" (that copy moved onto the option's own scale: discovery/value_scale.py).
POLICY_STARTS = ("zero", "top-level", "top-level-shifted")
# How Q(s, o) starts when the option joins: "max-sample" (the paper: the best Q(s, d) sampled
# when the target fired in gestation, everywhere) or "agent" (the agent's own state value
# max_a Q(s, a) over the primitives, fitted in its basis, plus ``value_bonus``).
VALUE_STARTS = ("max-sample", "agent")
# The Pinball observation box (positions in [0, 1], velocities scaled into
# [(1 - sqrt 2) / 2, (1 + sqrt 2) / 2]); the projection's grid spans it.
_OBS_LOW = (0.0, 0.0, (1.0 - 2.0**0.5) / 2.0, (1.0 - 2.0**0.5) / 2.0)
_OBS_HIGH = (1.0, 1.0, (1.0 + 2.0**0.5) / 2.0, (1.0 + 2.0**0.5) / 2.0)


def gestation_over(bank: OptionBank, episode: Tensor, ended: Tensor,
                   gestation: int = GESTATION_EPISODES) -> Tensor:  # fmt: skip
    """``[P, K]``: gestating options that join the repertoire now.

    Args:
        episode: ``LongTensor [P]``, the 0-based index of the episode that just ended.
        ended: ``BoolTensor [P]``, agents whose episode just ended.
        gestation: whole episodes of gestation after the creating one (paper: 10).
    """
    due = (episode[:, None] - bank.created_episode) >= gestation
    return ended[:, None] & (bank.status == OptionStatus.GESTATING) & due


@torch.no_grad()
def initialise_option_values(q_head: LinearQHead, mask: Tensor, value: Tensor,
                             num_primitives: int = NUM_PRIMITIVES) -> None:  # fmt: skip
    """Set ``Q(s, o_k) = value[p, k]`` for every state, for the slots in ``mask [P, K]``,
    through the head's :meth:`~skillchain_torch.interfaces.ValueHead.set_values` (the top-level
    head holds decisions ``num_primitives + k``)."""
    primitives = mask.new_zeros(mask.shape[0], num_primitives)
    q_head.set_values(torch.cat([primitives, mask], dim=1),
                      torch.cat([value.new_zeros(primitives.shape), value], dim=1))




def observation_box(dim: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(low, high)`` of the observation: Pinball's (its velocities reach past [0, 1]) for 4
    dims, the unit box (an env's observation scaled by its bounds) otherwise."""
    return (_OBS_LOW, _OBS_HIGH) if dim == 4 else ((0.0,) * dim, (1.0,) * dim)


def grid_points(dim: int) -> int:
    """Grid points per dim of the least-squares fits: 7 up to Pinball's 4 dims, 3 beyond
    (``7 ** 6`` states would not fit in memory beside a 6-d basis)."""
    return 7 if dim <= 4 else 3


def box_grid(dim: int, points: int, low: tuple[float, ...] | None = None,
             high: tuple[float, ...] | None = None, dtype: torch.dtype = torch.float64,
             device: torch.device | str | None = None) -> Tensor:  # fmt: skip
    """``[points ** dim, dim]``: the regular grid over the box ``[low, high]`` (default: the
    :func:`observation_box`), ``points`` a dim, the last dim varying fastest: the states every
    least-squares start here is fitted on.

    Example:
        >>> box_grid(2, 3, low=(0.0, 0.0), high=(1.0, 2.0))[:4].tolist()
        [[0.0, 0.0], [0.0, 1.0], [0.0, 2.0], [0.5, 0.0]]
    """
    box = observation_box(dim)
    low, high = box[0] if low is None else low, box[1] if high is None else high
    axes = [torch.linspace(lo, hi, points, dtype=dtype) for lo, hi in zip(low, high)]
    return torch.cartesian_prod(*axes).reshape(-1, dim).to(device)


def value_projection(top: FourierBasis, option: FourierBasis, points: int | None = None,
                     low: tuple[float, ...] | None = None,
                     high: tuple[float, ...] | None = None) -> Tensor:  # fmt: skip
    """``[F_option, F_top]``: least-squares map from top-level weights to option weights.

    A linear value ``w . phi_top(s)`` is fitted by ``(M w) . phi_option(s)`` over a regular grid
    of ``points ** dim`` states spanning the box ``[low, high]`` (uniform weight over the
    observation space). Deterministic: no random numbers are drawn.

    Example:
        >>> from skillchain_torch.features import FourierBasis
        >>> M = value_projection(FourierBasis(4, 2), FourierBasis(4, 1), points=4)
        >>> M.shape
        torch.Size([16, 81])
        >>> w = torch.zeros(81, dtype=torch.float64); w[0] = 3.0      # a constant 3
        >>> round(float((M @ w)[0]), 9), round(float((M @ w)[1:].abs().max()), 9)
        (3.0, 0.0)
    """
    points = grid_points(top.dim) if points is None else points
    low = observation_box(top.dim)[0] if low is None else low
    high = observation_box(top.dim)[1] if high is None else high
    if top.dim != option.dim or len(low) != top.dim or len(high) != top.dim or points < 2:
        raise ValueError(f"value_projection needs bases of one dimension matching low/high "
                         f"and points >= 2, got dims {top.dim}, {option.dim}, points {points}")
    dtype = top.coefficients.dtype
    grid = box_grid(top.dim, points, low, high, dtype, top.coefficients.device)
    pinv, phi_top = torch.linalg.pinv(option(grid)), top(grid).T.contiguous()  # [Fo, N], [Ft, N]
    # pinv (an SVD) and rowwise_dot give the same bits on every call; lstsq and matmul did not
    # (their rounding varies with the call and the operands' addresses). One option feature
    # at a time: each row's sum is the same, and the product stays in cache (6x faster).
    # Each row goes straight into the result: a list of small results between the large
    # products kept the allocator from reusing their memory (23 GB at 6 dims, 4,096 rows).
    out = torch.empty(pinv.shape[0], phi_top.shape[0], dtype=dtype, device=pinv.device)
    for i, chunk in enumerate(pinv.split(1)):
        out[i] = rowwise_dot(chunk[:, None, :], phi_top[None])[0]
    return out


_PROJECTIONS: dict[tuple, Tensor] = {}


def cached_projection(top: FourierBasis, option: FourierBasis) -> Tensor:
    """:func:`value_projection` with its defaults, computed once per process and basis pair
    (a few seconds at orders 4 and 3); the result is the same bits every time."""
    key = (top.dim, top.order, option.order, top.coefficients.dtype, str(top.coefficients.device))
    if key not in _PROJECTIONS:
        _PROJECTIONS[key] = value_projection(top, option)
    return _PROJECTIONS[key]


@torch.no_grad()
def initialise_option_policies(option_head, q_head: LinearQHead, mask: Tensor,
                               projection: Tensor,
                               num_primitives: int = NUM_PRIMITIVES) -> None:  # fmt: skip
    """Option ``k`` of agent ``p`` (``mask [P, K]``) starts from agent p's primitive values.

    ``option_head.weight[p, k, a] = projection @ q_head.weight[p, a]`` for every primitive a:
    the option's greedy policy starts as (the option basis's best fit of) the agent's own. A
    goal option's reward is the task's plus its completion reward, so the agent's values are
    its values up to that bonus; a chained option's target lies on the agent's way to the goal.
    Each (p, k) is computed alone, so an agent's weights do not depend on the population.

    Example:
        >>> from skillchain_torch.features import FourierBasis
        >>> from skillchain_torch.options import FourierOptionQHead
        >>> top, opt = FourierBasis(4, 2), FourierOptionQHead(1, 2, order=1)
        >>> head = LinearQHead(num_features=81, num_decisions=5 + 2, population=1)
        >>> head.weight.data[0, 3, 0] = 4.0                       # Q(s, a=3) = 4 everywhere
        >>> M = value_projection(top, opt.basis, points=4)
        >>> initialise_option_policies(opt, head, torch.tensor([[False, True]]), M)
        >>> opt(torch.full((1, 4), 0.3, dtype=torch.float64))[0].round(decimals=6).tolist()
        [[0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 4.0, 0.0]]
    """
    weight = option_head.weight  # [P, K, A, F_option]
    top = q_head.weight[:, :num_primitives, :]  # [P, A, F_top]
    for p, k in mask.nonzero().tolist():
        # rowwise_dot, not a BLAS matmul: BLAS rounds differently with the operand's address
        # (agent p's offset in the population), and agents must not depend on the population.
        w = rowwise_dot(top[p].to(projection.dtype)[:, None, :], projection[None])  # [A, F_o]
        weight[p, k] = w.to(weight.dtype)


# ----------------------------------------------------------------------------------------------
# The same two starts for heads that are not linear in a Fourier basis (a neural top level or
# option head): the agent's values are read on a grid of states and each written head fits them
# in its own last layer (``fit_values``: least squares, the hidden layers unchanged). With both
# heads linear in Fourier bases the fits above are used, exactly as before.
# ----------------------------------------------------------------------------------------------

FIT_STATES = 2048  # about this many grid states: a 64-unit layer needs more than 65


def fit_grid(dim: int, dtype: torch.dtype = torch.float64,
             device: torch.device | str | None = None) -> Tensor:  # fmt: skip
    """``[N, dim]``: the regular grid over the observation box the neural starts are fitted
    on, ``ceil(2048 ** (1 / dim))`` points a dim (at least 3): 2,116 states on MountainCar,
    2,401 on Pinball, 6,561 on LunarLander.

    Example:
        >>> fit_grid(2).shape, fit_grid(4).shape
        (torch.Size([2116, 2]), torch.Size([2401, 4]))
    """
    points = max(3, math.ceil(FIT_STATES ** (1.0 / dim) - 1e-9))
    return box_grid(dim, points, dtype=dtype, device=device)


@torch.no_grad()
def grid_values(q_head, phi: Tensor, p: int) -> Tensor:
    """``[N, D]``: agent p's top-level values ``Q(s, d)`` at the grid's features ``phi [N, F]``
    (agent p alone: a copy of its head, or its own weights for the linear head)."""
    if isinstance(q_head, LinearQHead):  # chunks: N x D x F products stay small
        w = q_head.weight[p].to(phi.dtype)
        return torch.cat([rowwise_dot(chunk[:, None, :], w[None]) for chunk in phi.split(256)])
    one = q_head.select_agents([p])
    return one(phi[:, None, :])[:, 0, :].to(torch.float64)


@torch.no_grad()
def fitted_starts(join: Tensor, q_head, option_head, features, grid: Tensor,
                  num_primitives: int, value_bonus: float | None,
                  policy: bool) -> None:  # fmt: skip
    """The joining options ``join [P, K]`` start from the agent's values, for any heads with
    ``fit_values`` (:class:`~skillchain_torch.modules.MLPQHead`,
    :class:`~skillchain_torch.options.MLPOptionQHead`): with ``value_bonus`` not None,
    ``Q(s, o) ~ max_a Q(s, a) + value_bonus`` in the top head (``value_start="agent"``); with
    ``policy``, the option's ``Q_o(s, a) ~ Q(s, a)`` (``policy_start="top-level"``).

    Example:
        >>> from skillchain_torch.modules import MLPQHead
        >>> from skillchain_torch.options import MLPOptionQHead
        >>> top = MLPQHead(num_features=4, num_decisions=5 + 2, population=1, hidden=8)
        >>> top.set_values(torch.tensor([[False, False, True, False, False, False, False]]),
        ...                torch.full((1, 7), 30.0, dtype=torch.float64))  # Q(s, a=2) = 30
        >>> opt = MLPOptionQHead(population=1, slots=2, hidden=8, layers=1)
        >>> fitted_starts(torch.tensor([[False, True]]), top, opt, torch.nn.Identity(),
        ...               fit_grid(4), 5, value_bonus=5.0, policy=True)
        >>> s = torch.full((1, 4), 0.4, dtype=torch.float64)
        >>> round(float(top(s).detach()[0, 6]), 3), opt(s)[0, 1].argmax().item()
        (35.0, 2)
    """
    phi = features(grid)
    for p in join.any(-1).nonzero()[:, 0].tolist():
        values = grid_values(q_head, phi, p)[:, :num_primitives]  # [N, A]
        rows = join[p : p + 1].new_zeros(join.shape)
        rows[p] = join[p]
        if value_bonus is not None:
            best = values.amax(-1, keepdim=True) + value_bonus  # [N, 1]
            target = best.expand(-1, q_head.num_decisions).expand(join.shape[0], -1, -1)
            mask = torch.cat([rows.new_zeros(rows.shape[0], num_primitives), rows], dim=1)
            q_head.fit_values(mask, phi, target)
        if policy:
            option_head.fit_values(rows, grid, values.expand(join.shape[0], -1, -1))


class StateValueFit:
    """Fit ``max_a Q(s, a)`` over the primitives as one linear value in the agent's basis.

    The fit is least squares over the same regular grid as :func:`value_projection`; its
    pseudo-inverse is computed once. :meth:`__call__` returns ``[F]`` weights for one agent.

    Example:
        >>> from skillchain_torch.features import FourierBasis
        >>> fit = StateValueFit(FourierBasis(4, 1), points=3)
        >>> w = torch.zeros(5, 16, dtype=torch.float64); w[2, 0] = 5.0; w[4, 0] = 7.0
        >>> round(float(fit(w)[0]), 9), round(float(fit(w)[1:].abs().max()), 9)
        (7.0, 0.0)
    """

    BLOCK = 128  # grid states (or output features) per product

    def __init__(self, basis: FourierBasis, points: int | None = None,
                 low: tuple[float, ...] | None = None,
                 high: tuple[float, ...] | None = None):  # fmt: skip
        grid = box_grid(basis.dim, points or grid_points(basis.dim), low, high,
                        basis.coefficients.dtype, basis.coefficients.device)
        self.phi = basis(grid)  # [N, F]
        self.pinv = torch.linalg.pinv(self.phi)  # [F, N]

    def __call__(self, primitive_weights: Tensor) -> Tensor:
        """``[F]`` weights of the fitted ``max_a Q(s, a)`` from ``[A, F]`` primitive weights."""
        # rowwise_dot, not matmul: the same bits whatever the weights' address (see
        # initialise_option_policies).
        w = primitive_weights.to(self.phi.dtype).contiguous()
        # In blocks of grid states: each row's sum is the same, and the [n, A, F] products stay
        # in cache (4x faster than one [N, A, F] product).
        values = torch.cat([rowwise_dot(phi[:, None, :], w[None]).amax(-1)
                            for phi in self.phi.split(self.BLOCK)])  # [N]
        return torch.cat([rowwise_dot(pinv, values[None, :])
                          for pinv in self.pinv.split(self.BLOCK)])


def state_value_fit(basis: FourierBasis, points: int | None = None) -> StateValueFit:
    """A :class:`StateValueFit` over ``basis`` (``points ** dim`` grid states)."""
    return StateValueFit(basis, points)
