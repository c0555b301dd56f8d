"""Option policies: a Q-function over the primitive actions for every option slot of every agent.

The paper (section 5.1) learns each option's policy by Q-learning with a 3rd-order Fourier basis
(256 features per action, ``alpha_o = 0.0005``). :class:`FourierOptionQHead` is that learner,
batched over ``[P, K]``; :class:`~skillchain_torch.options.mlp_q_head.MLPOptionQHead` is a
neural drop-in with the same interface.

Example:
    >>> import torch
    >>> head = FourierOptionQHead(population=2, slots=3, order=1, alpha=0.5)
    >>> obs = torch.zeros(2, 4, dtype=torch.float64)
    >>> head(obs).shape                                    # [P, K, A]
    torch.Size([2, 3, 5])
    >>> mask = torch.tensor([[True, False, False], [False, False, False]])
    >>> delta = head.td_update(obs, torch.tensor([4, 0]), torch.full((2, 3), 2.0), mask)
    >>> delta.tolist()                                     # 0 outside the mask
    [[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    >>> head(obs)[0, 0, 4].item()                          # 16 features of 1 * 0.5 * 2
    16.0
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import torch
from torch import Tensor, nn

from skillchain_torch.features import FourierBasis
from skillchain_torch.invariant import least_squares, rowwise_dot
from skillchain_torch.options.status import agent_index, check_slot_mask, slot_mask

NUM_ACTIONS = 5
OBS_DIM = 4
_DTYPES = {"float64": torch.float64, "float32": torch.float32}


def dtype_name(dtype: torch.dtype) -> str:
    for name, value in _DTYPES.items():
        if value == dtype:
            return name
    raise ValueError(f"unsupported dtype {dtype}; use float64 or float32")


class OptionQHead(nn.Module, ABC):
    """Interface of an option Q-head: ``Q_k(s, a)`` for every agent p and slot k.

    Attributes:
        population (P), slots (K), num_actions (A), obs_dim (D, the observation size).
        config: the constructor's keyword arguments (plain Python values), used to rebuild the
            head when an :class:`~skillchain_torch.options.OptionBank` is loaded.

    Subclasses implement :meth:`forward`, :meth:`td_update`, :meth:`reset_slots`,
    :meth:`select_agents` and :meth:`slot_tensors` (abstract: instantiating a head without one
    is a ``TypeError`` naming it); the encoded paths have defaults. Register the class
    (:func:`~skillchain_torch.options.register_q_head`) to load saved banks holding it.
    """

    population: int
    slots: int
    num_actions: int
    obs_dim: int = OBS_DIM
    config: dict[str, Any]

    def _check_obs(self, obs: Tensor) -> None:
        if tuple(obs.shape) != (self.population, self.obs_dim):
            raise ValueError(f"obs must be [P={self.population}, {self.obs_dim}], got "
                             f"{tuple(obs.shape)}")  # fmt: skip

    def _check_update(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        self._check_obs(obs)
        if tuple(action.shape) != (self.population,):
            raise ValueError(f"action must be [P={self.population}], got {tuple(action.shape)}")
        check_slot_mask(target, self.population, self.slots, "target")
        mask = check_slot_mask(mask, self.population, self.slots)
        act = action.to(torch.int64)
        if bool(((act < 0) | (act >= self.num_actions))[mask.any(-1)].any()):
            raise ValueError(f"actions must lie in [0, {self.num_actions}) for updated agents")
        return mask

    @abstractmethod
    def forward(self, obs: Tensor) -> Tensor:
        """``obs [P, 4] -> q [P, K, A]``: every slot's action values for every agent."""

    @abstractmethod
    def td_update(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        """Move ``Q_k(s_p, a_p)`` towards ``target[p, k]`` for every ``(p, k)`` in ``mask``.

        Args:
            obs: ``[P, 4]`` the state s where ``action`` was taken.
            action: ``LongTensor [P]``, the primitive action taken by agent p (by whoever acted:
                the update is off-policy).
            target: ``[P, K]`` TD targets (ignored, may be inf/NaN, outside ``mask``).
            mask: ``BoolTensor [P, K]``; other slots are left bit-for-bit unchanged.

        Returns:
            the TD errors ``target - Q_k(s, a)`` before the update, ``[P, K]``, 0 off-mask.
        """

    @abstractmethod
    def reset_slots(self, mask: Tensor) -> None:
        """Re-initialise the weights of the slots in ``mask [P, K]`` (a new option)."""

    @abstractmethod
    def select_agents(self, index, seeds: Tensor | None = None) -> OptionQHead:
        """A new head holding agents ``index`` (repeats allowed: replicate one agent)."""

    # Encoded paths: an agent encodes each visited state once (``encode``) and reuses the
    # code for acting, bootstrapping and updating. The defaults encode nothing (the code is
    # the observation); the Fourier head's code is its feature vector.
    def encode(self, obs: Tensor) -> Tensor:
        """What the head computes from an observation ``[P, 4]`` before its weights apply."""
        self._check_obs(obs)
        return obs

    def forward_code(self, code: Tensor) -> Tensor:
        """:meth:`forward` from a code of :meth:`encode`: ``[P, K, A]``."""
        return self(code)

    def slot_values(self, code: Tensor, slot: Tensor) -> Tensor:
        """``Q_{slot[p]}(s_p, .)``: the values of one slot per agent, ``[P, A]``."""
        q = self.forward_code(code)
        k = slot.clamp(min=0)[:, None, None].expand(-1, 1, q.shape[-1])
        return q.gather(1, k)[:, 0]

    def slot_values_rows(self, code: Tensor, slot: Tensor, index: Tensor) -> Tensor:
        """:meth:`slot_values` of the agents ``index [n]`` only: ``[n, A]``."""
        return self.slot_values(code, slot)[index]

    def max_values(self, code: Tensor, mask: Tensor) -> Tensor:
        """``max_a Q_k(s_p, a)`` for the ``(p, k)`` in ``mask [P, K]``; others unspecified."""
        return self.forward_code(code).amax(-1)

    def td_update_code(self, code: Tensor, action: Tensor, target: Tensor,
                       mask: Tensor) -> Tensor:  # fmt: skip
        """:meth:`td_update` from a code of :meth:`encode`."""
        return self.td_update(code, action, target, mask)

    @abstractmethod
    def slot_tensors(self) -> dict[str, Tensor]:
        """The learnable state as tensors with leading dims ``[P, K]`` (views, by name).

        :meth:`read_slots` / :meth:`write_slots` use it to save and restore one slot per agent
        (skill chaining drops the updates of an unsuccessful execution, paper 5.1), and the
        divergence check reads it.
        """

    def read_slots(self, slot: Tensor) -> dict[str, Tensor]:
        """A copy of slot ``slot[p]`` of every agent p: ``{name: [P, ...]}``
        (``slot`` is a ``LongTensor [P]``; negative entries read slot 0)."""
        agents = torch.arange(self.population, device=slot.device)
        k = slot.clamp(min=0)
        return {name: t[agents, k].clone() for name, t in self.slot_tensors().items()}

    @torch.no_grad()
    def write_slots(self, slot: Tensor, values: dict[str, Tensor], mask: Tensor) -> None:
        """Put ``values`` (from :meth:`read_slots`) back into slot ``slot[p]`` of the agents
        in ``mask [P]``; other agents and slots are untouched."""
        index = mask.to(torch.bool).nonzero()[:, 0]
        k = slot[index].clamp(min=0)
        for name, t in self.slot_tensors().items():
            t[index, k] = values[name][index].to(t.dtype)

    def reset_slot(self, agents: int | Tensor, slot: int | Tensor) -> None:
        """Reset slot ``slot`` (int or ``[P]``) of ``agents`` (index or ``BoolTensor [P]``)."""
        self.reset_slots(slot_mask(agents, slot, self.slots, self.population, self._device()))

    def q_value(self, obs: Tensor, action: Tensor) -> Tensor:
        """``Q_k(s_p, a_p)`` for every slot: ``[P, K]``."""
        q = self(obs)
        return q.gather(2, action.to(torch.int64)[:, None, None].expand(-1, self.slots, 1))[..., 0]

    def _device(self) -> torch.device:
        return next(iter(self.state_dict().values())).device

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.config.items())


class FourierOptionQHead(OptionQHead):
    """Linear option Q-functions over a Fourier basis of the observation (the paper's learner).

    Args:
        population: P agents.
        slots: K option slots per agent.
        order: Fourier order (paper: 3, i.e. ``4**4 = 256`` features per action).
        num_actions: A primitive actions (5 in Pinball).
        alpha: step size (paper: ``alpha_o = 0.0005``).
        dtype, device: of the weights.

    ``weight [P, K, A, F]`` is a zero-initialised buffer and :meth:`td_update` is the closed-form
    step ``weight[p, k, a_p] += alpha * delta[p, k] * phi(s_p)`` for masked ``(p, k)``. Only
    elementwise products and :func:`~skillchain_torch.invariant.rowwise_dot` are used, so agent
    p's values and weights are bit-identical whether it runs alone or in a population.
    """

    def __init__(
        self,
        population: int,
        slots: int,
        order: int = 3,
        num_actions: int = NUM_ACTIONS,
        alpha: float = 0.0005,
        dtype: torch.dtype | str = torch.float64,
        device: torch.device | str | None = None,
        obs_dim: int = OBS_DIM,
    ):
        super().__init__()
        dtype = _DTYPES[dtype] if isinstance(dtype, str) else dtype
        if population < 1 or slots < 1 or num_actions < 1 or obs_dim < 1:
            raise ValueError("population, slots, num_actions and obs_dim must be >= 1")
        self.population, self.slots, self.num_actions = population, slots, num_actions
        self.obs_dim = int(obs_dim)
        self.alpha = float(alpha)
        self.config = dict(
            population=population, slots=slots, order=order, num_actions=num_actions,
            alpha=self.alpha, dtype=dtype_name(dtype),
        )  # fmt: skip
        if self.obs_dim != OBS_DIM:  # (Pinball's files keep their config as it was)
            self.config["obs_dim"] = self.obs_dim
        self.basis = FourierBasis(self.obs_dim, order, dtype=dtype).to(device)
        self.num_features = self.basis.num_features
        shape = (population, slots, num_actions, self.num_features)
        self.register_buffer("weight", torch.zeros(shape, dtype=dtype, device=device))

    def features(self, obs: Tensor) -> Tensor:
        self._check_obs(obs)
        return self.basis(obs.to(self.weight.device))

    def forward(self, obs: Tensor) -> Tensor:
        return self.forward_code(self.features(obs))

    def encode(self, obs: Tensor) -> Tensor:
        return self.features(obs)

    def forward_code(self, code: Tensor) -> Tensor:
        return rowwise_dot(self.weight, code[:, None, None, :])

    def slot_values(self, code: Tensor, slot: Tensor) -> Tensor:
        agents = torch.arange(self.population, device=self.weight.device)
        return rowwise_dot(self.weight[agents, slot.clamp(min=0)], code[:, None, :])

    def slot_values_rows(self, code: Tensor, slot: Tensor, index: Tensor) -> Tensor:
        # Gather just these rows' weights; each value is the same row sum as in slot_values.
        return rowwise_dot(self.weight[index, slot[index].clamp(min=0)], code[index][:, None, :])

    def max_values(self, code: Tensor, mask: Tensor) -> Tensor:
        # Only the masked slots: each row's sum is the same wherever it sits (rowwise_dot).
        out = torch.zeros(mask.shape, dtype=self.weight.dtype, device=self.weight.device)
        pi, ki = mask.nonzero().unbind(-1)
        out[pi, ki] = rowwise_dot(self.weight[pi, ki], code[pi][:, None, :]).amax(-1)
        return out

    @torch.no_grad()
    def td_update(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        mask = self._check_update(obs, action, target, mask)
        return self._td_step(self.features(obs), action, target, mask)

    @torch.no_grad()
    def td_update_code(self, code: Tensor, action: Tensor, target: Tensor,
                       mask: Tensor) -> Tensor:  # fmt: skip
        return self._td_step(code, action, target, mask.to(torch.bool))

    def _td_step(self, phi: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        # Only the masked (agent, slot) rows of the taken action are read and written back.
        pi, ki = mask.nonzero().unbind(-1)
        act = action.to(torch.int64)[pi]
        rows = self.weight[pi, ki, act]  # [M, F]
        x = phi[pi]
        delta_m = target[pi, ki].to(rows.dtype) - rowwise_dot(rows, x)
        self.weight[pi, ki, act] = rows + (self.alpha * delta_m)[:, None] * x
        delta = torch.zeros(mask.shape, dtype=rows.dtype, device=rows.device)
        delta[pi, ki] = delta_m
        return delta

    @torch.no_grad()
    def fit_values(self, mask: Tensor, obs: Tensor, values: Tensor) -> None:
        """``Q_k(s, a) ~ values[p, n, a]`` on the states ``obs [N, D]`` for the slots in ``mask
        [P, K]``: least squares in the basis (a policy copied from a top level that is not
        linear in a Fourier basis, ``policy_start="top-level"``)."""
        mask = check_slot_mask(mask, self.population, self.slots)
        phi = self.basis(obs.to(self.weight))
        for p, k in mask.nonzero().tolist():
            self.weight[p, k] = least_squares(phi, values[p].to(phi)).T.to(self.weight)

    def slot_tensors(self) -> dict[str, Tensor]:
        return {"weight": self.weight}

    @torch.no_grad()
    def reset_slots(self, mask: Tensor) -> None:
        mask = check_slot_mask(mask, self.population, self.slots)
        pi, ki = mask.nonzero().unbind(-1)
        self.weight[pi, ki] = 0.0

    def select_agents(self, index, seeds: Tensor | None = None) -> FourierOptionQHead:
        index = agent_index(index, self.population).to(self.weight.device)
        new = type(self)(**{**self.config, "population": len(index)}, device=self.weight.device)
        new.weight.copy_(self.weight[index])
        return new
