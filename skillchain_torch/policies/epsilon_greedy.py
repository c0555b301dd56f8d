"""Epsilon-greedy choice among the available decisions (paper section 5.1: epsilon = 0.01).

Each agent uses exactly two uniforms per decision, ``u0`` for the exploration test and ``u1``
for the index among the candidates, so the random stream advances by a fixed amount per step
whatever happens (needed for the population reproducibility contract).

Example:
    >>> import torch
    >>> q = torch.tensor([[1.0, 3.0, 3.0], [5.0, 0.0, 9.0]], dtype=torch.float64)
    >>> available = torch.tensor([[True, True, True], [True, True, False]])
    >>> u = torch.tensor([[0.5, 0.75], [0.5, 0.0]], dtype=torch.float64)
    >>> epsilon_greedy(q, available, epsilon=0.0, uniforms=u).tolist()  # tie 1/2: u1 picks 2
    [2, 0]
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from skillchain_torch.rng import CounterRNG

NUM_UNIFORMS = 2


def epsilon_greedy(
    q: Tensor, available: Tensor, epsilon: float | Tensor, uniforms: Tensor, check: bool = True
) -> Tensor:
    """Pick one available decision per agent.

    Args:
        q: ``[P, D]`` action values.
        available: ``BoolTensor [P, D]``; unavailable decisions are never chosen.
        epsilon: exploration probability, a float or ``[P]``.
        uniforms: ``float64 [P, 2]`` in [0, 1): column 0 decides exploration (``u0 < epsilon``),
            column 1 picks uniformly among the candidates (all available decisions when
            exploring, else the available maximisers of ``q``: ties are broken uniformly).
        check: validate shapes, availability and NaNs (two host syncs); an agent's hot loop
            that guarantees them passes ``False``. The decision is the same either way.

    Returns:
        ``LongTensor [P]``.

    Raises:
        ValueError: an agent has no available decision, or NaN among its available values.
    """
    if check:
        if (q.ndim != 2 or available.shape != q.shape
                or uniforms.shape != (q.shape[0], NUM_UNIFORMS)):  # fmt: skip
            raise ValueError(
                f"expected q [P, D], available [P, D], uniforms [P, 2]; got {tuple(q.shape)}, "
                f"{tuple(available.shape)}, {tuple(uniforms.shape)}"
            )
        available = available.to(torch.bool)
        if not bool(available.any(-1).all()):
            agents = (~available.any(-1)).nonzero().flatten().tolist()
            raise ValueError(f"agents {agents} have no available decision")
    masked = torch.where(available, q, -torch.inf)
    if check and bool(masked.isnan().any()):
        raise ValueError("q has NaN among available decisions")
    # max and == are exact, so the set of maximisers is the same in any layout.
    greedy = available & (masked == masked.amax(-1, keepdim=True))
    if isinstance(epsilon, Tensor):
        epsilon = epsilon.to(dtype=uniforms.dtype, device=uniforms.device)
    explore = uniforms[:, 0] < epsilon
    candidates = torch.where(explore[:, None], available, greedy)
    count = candidates.sum(-1)
    # k-th candidate with k = floor(u1 * count); the clamp guards u1 * count rounding up.
    k = torch.minimum(torch.floor(uniforms[:, 1] * count).to(torch.int64), count - 1)
    rank = torch.cumsum(candidates.to(torch.int64), dim=-1) - 1
    return (candidates & (rank == k[:, None])).to(torch.int64).argmax(-1)


class EpsilonGreedy(nn.Module):
    """Module form of :func:`epsilon_greedy`; ``forward(q, available, uniforms) -> decision``.

    Example:
        >>> import torch
        >>> policy = EpsilonGreedy(epsilon=0.01)
        >>> rng = CounterRNG.from_seed(0, population=2)
        >>> q = torch.tensor([[0.0, 1.0], [2.0, 1.0]], dtype=torch.float64)
        >>> policy.sample(q, torch.ones(2, 2, dtype=torch.bool), rng).tolist()
        [1, 0]
        >>> rng.counter.tolist()
        [2, 2]
    """

    def __init__(self, epsilon: float | Tensor = 0.01):
        super().__init__()
        self.epsilon = epsilon

    def forward(self, q: Tensor, available: Tensor, uniforms: Tensor) -> Tensor:
        return epsilon_greedy(q, available, self.epsilon, uniforms)

    def sample(
        self, q: Tensor, available: Tensor, rng: CounterRNG, mask: Tensor | None = None
    ) -> Tensor:
        """Draw the two uniforms from ``rng`` (advancing only agents in ``mask``) and decide."""
        return self(q, available, rng.uniform(NUM_UNIFORMS, mask=mask))

    def extra_repr(self) -> str:
        return f"epsilon={self.epsilon}"


class EpsilonGreedyModule(TensorDictModule):
    """:class:`EpsilonGreedy` reading and writing TensorDict keys.

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> td = TensorDict({
        ...     "q_value": torch.tensor([[0.0, 1.0]], dtype=torch.float64),
        ...     "mask": torch.tensor([[True, False]]),
        ...     "uniforms": torch.tensor([[0.5, 0.5]], dtype=torch.float64),
        ... }, batch_size=[1])
        >>> EpsilonGreedyModule(epsilon=0.0)(td)["decision"].tolist()
        [0]
    """

    def __init__(
        self,
        epsilon: float | Tensor = 0.01,
        in_keys: Sequence[str] = ("q_value", "mask", "uniforms"),
        out_keys: Sequence[str] = ("decision",),
    ):
        super().__init__(EpsilonGreedy(epsilon), in_keys=list(in_keys), out_keys=list(out_keys))
