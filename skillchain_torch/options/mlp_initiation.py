"""``MLPInitiationClassifier``: a neural initiation set, one small MLP per ``(agent, slot)``.

The paper's initiation sets are logistic regressions on quadratic features of the state
(section 5.1). This is the same set with a neural model: a subclass of
:class:`~skillchain_torch.options.InitiationClassifier` that overrides only :meth:`logit`, so
it keeps every rule of the base class (the example stores and their refits, the 0.1 distance
constraint to a positive example, true everywhere until first fitted, the convergence test on
logits at fixed probe points) and is trained by binary cross-entropy on the same stores through
:func:`~skillchain_torch.options.initiation_fit.gradient_fit` (``sweeps`` Adam steps per fit).

Example:
    >>> import torch
    >>> clf = MLPInitiationClassifier(population=1, slots=1, capacity=200, hidden=16)
    >>> x = torch.rand(200, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    >>> inside = (x[:, 0] - 0.5) ** 2 + (x[:, 1] - 0.5) ** 2 < 0.1   # a disc: not linear
    >>> _ = clf.add_examples(0, 0, x, inside)
    >>> _ = clf.fit()
    >>> probe = torch.tensor([[[0.5, 0.5, 0.5, 0.5], [0.05, 0.95, 0.5, 0.5]]],
    ...                      dtype=torch.float64)
    >>> (clf.logit(probe)[0, :, 0] > 0).tolist()     # the centre is in, a corner is out
    [True, False]
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from skillchain_torch.modules.stacked import stacked_affine
from skillchain_torch.options.initiation import InitiationClassifier

__all__ = ["MLPInitiationClassifier"]


class MLPInitiationClassifier(InitiationClassifier):
    """Per-slot MLP initiation sets (tanh hidden layers, a log-odds output).

    Args:
        population, slots, ...: as :class:`InitiationClassifier` (``capacity``, ``distance``,
            ``sweeps``, ``initial_bias``, ``balanced``, ``seed``, ``obs_dim``, ...).
        hidden, layers: width and number of the hidden layers.
        lr: Adam's step size for each fit (the base class's SGD step suits a linear model only).

    The weights of all ``P x K`` networks are stacked (``[P, K, fan_in, fan_out]``) and applied
    with one batched matmul per layer. A slot's hidden layers start uniform in ``+-1/sqrt(fan_in)``
    from a generator keyed by the agent's seed, the slot and its generation (so a reused slot
    starts afresh, the same way in any population); its output layer starts at weight 0 and
    bias ``initial_bias``, so a fresh set's log-odds is ``initial_bias`` everywhere, like the
    logistic one.
    """

    def __init__(self, population: int, slots: int, hidden: int = 32, layers: int = 2,
                 lr: float = 0.01, sweeps: int = 100, **kwargs):  # fmt: skip
        super().__init__(population, slots, lr=lr, sweeps=sweeps, **kwargs)
        if hidden < 1 or layers < 1:
            raise ValueError(f"hidden and layers must be >= 1, got {hidden} and {layers}")
        self.config.update(hidden=int(hidden), layers=int(layers))
        sizes = [self.obs_dim] + [int(hidden)] * int(layers) + [1]
        dtype, device = self.examples.dtype, self.examples.device
        self.layer_weights = nn.ParameterList(
            nn.Parameter(torch.zeros(population, slots, i, o, dtype=dtype, device=device))
            for i, o in zip(sizes[:-1], sizes[1:]))  # fmt: skip
        self.layer_biases = nn.ParameterList(
            nn.Parameter(torch.zeros(population, slots, o, dtype=dtype, device=device))
            for o in sizes[1:])  # fmt: skip
        self._initialise(torch.ones(population, slots, dtype=torch.bool))

    @torch.no_grad()
    def _initialise(self, mask: Tensor) -> None:
        for p, k in mask.nonzero().tolist():
            key = (int(self.seeds[p]) * 1_000_003 + k) * 1_009 + int(self.generation[p, k])
            g = torch.Generator().manual_seed(key & 0x7FFF_FFFF_FFFF_FFFF)
            for weight, bias in zip(self.layer_weights[:-1], self.layer_biases[:-1]):
                bound = 1.0 / math.sqrt(weight.shape[2])
                w = torch.rand(weight.shape[2:], generator=g, dtype=torch.float64) * 2 - 1
                b = torch.rand(bias.shape[2:], generator=g, dtype=torch.float64) * 2 - 1
                weight[p, k], bias[p, k] = (bound * w).to(weight), (bound * b).to(bias)
            self.layer_weights[-1][p, k] = 0.0
            self.layer_biases[-1][p, k] = self.initial_bias

    def logit(self, obs: Tensor) -> Tensor:
        """``obs [P, *B, D] -> [P, *B, K]``: every slot's network on agent p's states."""
        obs = self._check_obs(obs)
        lead = obs.shape[1:-1]
        x = 2.0 * obs.reshape(self.population, -1, self.obs_dim) - 1.0  # [P, N, D] in [-1, 1]
        x = x[:, None].expand(-1, self.slots, -1, -1)  # each slot's network on the same states
        return self._networks(x).transpose(1, 2).reshape(self.population, *lead, self.slots)

    def own_logits(self, examples: Tensor, agents: Tensor) -> Tensor:
        """``examples [N, K, L, D]`` of agents ``agents [N]`` ``-> [N, K, L]``: slot k's
        network on slot k's examples only (what a fit needs; :meth:`logit` would run every slot
        on every slot's examples of every agent, K x P / N times the work)."""
        return self._networks(2.0 * examples.to(self.examples.dtype) - 1.0, agents)

    def _networks(self, x: Tensor, agents: Tensor | None = None) -> Tensor:
        """``x [N, K, L, D]`` (inputs in [-1, 1]) through agent ``agents[n]``'s slot-k network
        (every agent's, in order, without ``agents``: no copy of the weights every step):
        ``[N, K, L]``, one :func:`~skillchain_torch.modules.stacked.stacked_affine` per layer
        over the N * K networks. (Which agents fit together, and so the batch shape, depends on
        when their episodes end; a batched matmul may round differently for another shape.)"""
        N, K, L = x.shape[:3]
        x = x.reshape(N * K, L, -1)
        last = len(self.layer_weights) - 1
        for i, (weight, bias) in enumerate(zip(self.layer_weights, self.layer_biases)):
            w, b = (weight, bias) if agents is None else (weight[agents], bias[agents])
            x = stacked_affine(x, w.reshape(N * K, *w.shape[2:]), b.reshape(N * K, -1))
            if i < last:
                x = torch.tanh(x)
        return x[..., 0].reshape(N, K, L)

    def make_optimizer(self, params: list[nn.Parameter]) -> torch.optim.Optimizer:
        return torch.optim.Adam(params, lr=self.lr)

    @torch.no_grad()
    def reset_slots(self, mask: Tensor) -> None:
        super().reset_slots(mask)  # the stores, flags and generation; then fresh networks
        self._initialise(mask.to(self.seeds.device))
