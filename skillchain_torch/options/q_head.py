"""Option policies: a Q-function over the primitive actions for every option slot of every agent.

The paper (section 5.1) learns each option's policy by Q-learning with a 3rd-order Fourier basis
(256 features per action, ``alpha_o = 0.0005``). :class:`FourierOptionQHead` is that learner,
batched over ``[P, K]``; :class:`MLPOptionQHead` is a neural drop-in with the same interface.

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

import math
from abc import ABC, abstractmethod
from typing import Any

import torch
from torch import Tensor, nn
from torch.func import functional_call, grad, stack_module_state, vmap

from skillchain_torch.features import FourierBasis
from skillchain_torch.invariant import rowwise_dot
from skillchain_torch.options.status import agent_index, agent_seeds, check_slot_mask, slot_mask
from skillchain_torch.rng import CounterRNG

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


def _mlp(hidden: int, layers: int, num_actions: int, dtype: torch.dtype,
         obs_dim: int = OBS_DIM) -> nn.Sequential:  # fmt: skip
    sizes = [obs_dim] + [hidden] * layers
    modules: list[nn.Module] = []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        modules += [nn.Linear(fan_in, fan_out, dtype=dtype, device="meta"), nn.Tanh()]
    modules.append(nn.Linear(sizes[-1], num_actions, dtype=dtype, device="meta"))
    return nn.Sequential(*modules)


class MLPOptionQHead(OptionQHead):
    """Neural option Q-functions: one small MLP per ``(agent, slot)``, stacked with ``torch.func``.

    Args:
        population, slots, num_actions: as :class:`FourierOptionQHead`.
        hidden: width of the hidden layers; layers: how many (tanh activations).
        lr: SGD step size on the squared TD error ``0.5 * (target - Q_k(s, a))^2``.
        q_scale: the network outputs ``Q / q_scale``; with Pinball's returns (thousands) a scale
            of the order of the returns (e.g. 1000) keeps gradients tame.
        seed: int (agent p uses ``seed + p``) or ``LongTensor [P]``; initial weights of a slot
            come from a :class:`~skillchain_torch.rng.CounterRNG` stream of its agent.

    The P*K networks are ``torch.func.stack_module_state`` copies of one template held as
    parameters ``[P, K, ...]`` and evaluated with ``vmap(functional_call)``. Hidden layers start
    uniform in ``+-1/sqrt(fan_in)`` (PyTorch's default range); the output layer starts at zero so
    a fresh slot has ``Q = 0`` like the linear head. Each slot's loss depends only on its own
    parameters, so masked-out slots receive zero gradient and stay unchanged.

    Not bit-reproducible across population sizes: vmapped ``matmul`` and autograd reductions
    may block differently for different P (the initial weights are, the trained ones need not
    be). Use :class:`FourierOptionQHead` where the population contract matters.
    """

    def __init__(
        self,
        population: int,
        slots: int,
        hidden: int = 64,
        layers: int = 2,
        num_actions: int = NUM_ACTIONS,
        lr: float = 1e-3,
        q_scale: float = 1.0,
        seed: int | Tensor = 0,
        dtype: torch.dtype | str = torch.float64,
        device: torch.device | str | None = None,
        obs_dim: int = OBS_DIM,
    ):
        super().__init__()
        dtype = _DTYPES[dtype] if isinstance(dtype, str) else dtype
        if population < 1 or slots < 1 or num_actions < 1 or hidden < 1 or layers < 1:
            raise ValueError("population, slots, num_actions, hidden, layers must be >= 1")
        self.population, self.slots, self.num_actions = population, slots, num_actions
        self.obs_dim = int(obs_dim)
        self.lr, self.q_scale = float(lr), float(q_scale)
        self._dtype = dtype
        self.config = dict(
            population=population, slots=slots, hidden=hidden, layers=layers,
            num_actions=num_actions, lr=self.lr, q_scale=self.q_scale, dtype=dtype_name(dtype),
        )  # fmt: skip
        if self.obs_dim != OBS_DIM:
            self.config["obs_dim"] = self.obs_dim
        template = _mlp(hidden, layers, num_actions, dtype, self.obs_dim)
        object.__setattr__(self, "_template", template)  # not a submodule: no own state
        # One network's stacked layout ([1, ...] per parameter) widened to [P, K, ...].
        layout, _ = stack_module_state([template])
        self._names = list(layout)
        shapes = {self._key(n): (population, slots, *v.shape[1:]) for n, v in layout.items()}
        self.params = nn.ParameterDict(
            {k: nn.Parameter(torch.zeros(shape, dtype=dtype, device=device), requires_grad=False)
             for k, shape in shapes.items()}
        )  # fmt: skip
        seeds = agent_seeds(seed, population)
        self.register_buffer("rng_seeds", seeds.to(device))
        self.register_buffer("rng_counter", torch.zeros_like(self.rng_seeds))
        self.reset_slots(torch.ones(population, slots, dtype=torch.bool, device=device))

    @staticmethod
    def _key(name: str) -> str:
        return name.replace(".", "__")

    def _stacked(self) -> dict[str, Tensor]:
        n = self.population * self.slots
        stacked = {}
        for name in self._names:
            param = self.params[self._key(name)]
            stacked[name] = param.reshape(n, *param.shape[2:])
        return stacked

    def _net(self, params: dict[str, Tensor], x: Tensor) -> Tensor:
        return functional_call(self._template, params, (x,)) * self.q_scale

    def _inputs(self, obs: Tensor) -> Tensor:
        self._check_obs(obs)
        x = obs.to(self._dtype) * 2.0 - 1.0  # observations in [0, 1] -> [-1, 1]
        return x[:, None, :].expand(-1, self.slots, -1).reshape(-1, self.obs_dim)

    def forward(self, obs: Tensor) -> Tensor:
        q = vmap(self._net)(self._stacked(), self._inputs(obs))
        return q.reshape(self.population, self.slots, self.num_actions)

    def td_update(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        mask = self._check_update(obs, action, target, mask)
        dtype = self._dtype
        act = torch.where(mask.any(-1), action.to(torch.int64), torch.zeros_like(action))
        act = act[:, None].expand(-1, self.slots).reshape(-1)
        weight = mask.reshape(-1).to(dtype)
        goal = torch.where(mask, target.to(dtype), torch.zeros((), dtype=dtype)).reshape(-1)

        def slot_loss(params, x, a, y, m):
            q_sa = torch.gather(self._net(params, x), 0, a[None])[0]
            delta = y - q_sa
            return 0.5 * m * delta * delta, delta

        with torch.no_grad():
            grads, delta = vmap(grad(slot_loss, has_aux=True))(
                self._stacked(), self._inputs(obs), act, goal, weight
            )
            for name in self._names:
                param = self.params[self._key(name)]
                param.sub_(self.lr * grads[name].reshape(param.shape))
        delta = delta.reshape(self.population, self.slots)
        return torch.where(mask, delta, torch.zeros_like(delta))

    def slot_tensors(self) -> dict[str, Tensor]:
        return {key: param.data for key, param in self.params.items()}

    @torch.no_grad()
    def reset_slots(self, mask: Tensor) -> None:
        mask = check_slot_mask(mask, self.population, self.slots)
        output = f"{len(self._template) - 1}."  # the output layer's weight and bias start at 0
        sizes = [self.params[self._key(n)][0, 0].numel() for n in self._names]
        rng = CounterRNG(self.rng_seeds, stream=0x0B7, counter=self.rng_counter)
        for k in range(self.slots):
            chosen = mask[:, k]
            if not bool(chosen.any()):
                continue
            draws = rng.uniform(sum(sizes), mask=chosen) * 2.0 - 1.0  # [P, n] in [-1, 1)
            offset = 0
            for name, size in zip(self._names, sizes):
                param = self.params[self._key(name)]
                weight_name = name.rsplit(".", 1)[0] + ".weight"  # a bias uses its layer's fan-in
                fan_in = self.params[self._key(weight_name)].shape[-1]
                value = draws[:, offset : offset + size] / math.sqrt(fan_in)
                offset += size
                if name.startswith(output):
                    value = torch.zeros_like(value)
                value = value.to(param.dtype).reshape(self.population, *param.shape[2:])
                param[:, k] = torch.where(
                    chosen.reshape(-1, *[1] * (param.ndim - 2)), value, param[:, k]
                )
        self.rng_counter.copy_(rng.counter)

    def select_agents(self, index, seeds: Tensor | None = None) -> MLPOptionQHead:
        device = self.rng_seeds.device
        index = agent_index(index, self.population).to(device)
        new_seeds = self.rng_seeds[index] if seeds is None else torch.as_tensor(seeds)
        new = type(self)(**{**self.config, "population": len(index)}, seed=new_seeds,
                         device=device)  # fmt: skip
        with torch.no_grad():
            for key, param in self.params.items():
                new.params[key].copy_(param[index])
            if seeds is None:
                new.rng_counter.copy_(self.rng_counter[index])
        return new
