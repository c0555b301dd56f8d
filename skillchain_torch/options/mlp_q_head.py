"""``MLPOptionQHead``: neural option Q-functions, one small MLP per ``(agent, slot)``, their
weights stacked ``[P, K, ...]`` (a drop-in for :class:`~skillchain_torch.options.
FourierOptionQHead` behind the same :class:`~skillchain_torch.options.OptionQHead` interface).

Example:
    >>> import torch
    >>> head = MLPOptionQHead(population=2, slots=3, hidden=8, layers=1)
    >>> head(torch.zeros(2, 4, dtype=torch.float64)).shape      # [P, K, A]; zero at the start
    torch.Size([2, 3, 5])
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.func import stack_module_state
from torch.nn import functional

from skillchain_torch.invariant import affine_rows, least_squares
from skillchain_torch.modules.stacked import AugmentedCache, augment, augmented_affine
from skillchain_torch.options.q_head import _DTYPES, NUM_ACTIONS, OBS_DIM, OptionQHead, dtype_name
from skillchain_torch.options.status import agent_index, agent_seeds, check_slot_mask
from skillchain_torch.rng import CounterRNG

__all__ = ["MLPOptionQHead"]


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
        lr: SGD step size on the loss of the scaled TD error ``delta / q_scale``.
        q_scale: the network outputs ``Q / q_scale`` and learns from ``delta / q_scale``. With
            Pinball's returns (of order 10^4: an option's target earns ``r + C``) a scale of
            1000 (the default) keeps the network's outputs and errors of order 10.
        loss_function: ``"smooth_l1"`` (Huber at 1 on the scaled error, the default: a
            gradient never larger than ``lr`` times the network's) or ``"l2"``
            (``0.5 (delta / q_scale)^2``).
        seed: int (agent p uses ``seed + p``) or ``LongTensor [P]``; initial weights of a slot
            come from a :class:`~skillchain_torch.rng.CounterRNG` stream of its agent.

    The P*K networks are ``torch.func.stack_module_state`` copies of one template held as
    parameters ``[P, K, ...]`` and evaluated with one batched matmul per layer; a TD update is one
    autograd pass over all of them (it was ``vmap(grad(...))``: 3 ms a step at P = 1, mostly
    ``torch.func``'s bookkeeping). Before the scaled loss, the loss was ``0.5 delta^2`` on
    unscaled errors, so at ``q_scale=1000`` a TD error of 10^4 made a step 10^7 times ``lr``
    (NaN after 78 updates). Hidden layers start
    uniform in ``+-1/sqrt(fan_in)`` (PyTorch's default range); the output layer starts at zero so
    a fresh slot has ``Q = 0`` like the linear head. Each slot's loss depends only on its own
    parameters, so masked-out slots receive zero gradient and stay unchanged.

    Agents are independent (each slot's loss reads only its own parameters, and each agent's
    replay memory is its own), and within one population size bit for bit; across sizes the
    batched matmuls may round the last bits differently (the initial weights are the same, the
    trained ones need not be). Use :class:`FourierOptionQHead` where the population contract
    matters.
    """

    def __init__(
        self,
        population: int,
        slots: int,
        hidden: int = 64,
        layers: int = 2,
        num_actions: int = NUM_ACTIONS,
        lr: float = 1e-3,
        q_scale: float = 1000.0,
        seed: int | Tensor = 0,
        dtype: torch.dtype | str = torch.float64,
        device: torch.device | str | None = None,
        obs_dim: int = OBS_DIM,
        loss_function: str = "smooth_l1",
    ):
        super().__init__()
        if loss_function not in ("smooth_l1", "l2"):
            raise ValueError(f"loss_function must be 'smooth_l1' or 'l2', got {loss_function!r}")
        self.loss_function = loss_function
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
            loss_function=loss_function,
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
        # How many times each slot was reset (a new option took it): replayed transitions of
        # a slot's earlier occupant are not learned from (OptionReplay).
        self.register_buffer("slot_epoch", torch.zeros(population, slots, dtype=torch.int64,
                                                       device=device))  # fmt: skip
        self.replay = None  # an OptionReplay: learn from sampled minibatches, not each step
        self._augmented = AugmentedCache()  # (acting forwards reuse the weights between writes)
        self.reset_slots(torch.ones(population, slots, dtype=torch.bool, device=device))

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        key = prefix + "slot_epoch"  # banks saved before the epochs were kept: no resets yet
        if key not in state_dict:
            state_dict[key] = torch.ones_like(self.slot_epoch)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    @staticmethod
    def _key(name: str) -> str:
        return name.replace(".", "__")

    def _layers(self) -> list[tuple[Tensor, Tensor]]:
        """``(weight [P, K, out, in], bias [P, K, out])`` per layer, in order."""
        return [(self.params[self._key(f"{i}.weight")], self.params[self._key(f"{i}.bias")])
                for i in range(0, len(self._template), 2)]  # fmt: skip

    def _values(self, obs: Tensor, layers=None) -> Tensor:
        """``obs [*B, P, D] -> Q [*B, P, K, A]``: every (agent, slot) network at once, each on
        its agent's states (one batched matmul per layer, the bias inside it:
        :mod:`skillchain_torch.modules.stacked`)."""
        layers = self._layers() if layers is None else layers
        P, K = self.population, self.slots
        x = (obs.to(self._dtype) * 2.0 - 1.0)  # observations in [0, 1] -> [-1, 1]
        lead = x.shape[:-2]
        x = x.reshape(-1, P, x.shape[-1]).transpose(0, 1)  # [P, N, D]
        N = x.shape[1]
        augmented = self._augmented.get([t for pair in layers for t in pair],
                                        lambda: self._augment(layers))  # fmt: skip
        x = augmented_affine(x, augmented[0])  # [P, N, K * O]: the first layer, all K at once
        out = layers[0][0].shape[2]
        x = x.reshape(P, N, K, out).transpose(1, 2).reshape(P * K, N, out)
        for w in augmented[1:]:  # [P * K] networks, each on its agent's N states
            x = augmented_affine(torch.tanh(x), w)
        x = x.reshape(P, K, N, -1).permute(2, 0, 1, 3).reshape(*lead, P, K, -1)
        return x * self.q_scale

    def _augment(self, layers) -> list[Tensor]:
        """Each layer's weight and bias as one ``[G, in + 1, out]`` matrix: the first over the
        P agents (all K slots' outputs side by side), the others over the P * K networks."""
        P, K = self.population, self.slots
        weight, bias = layers[0]  # [P, K, O, D], [P, K, O]
        out = [augment(weight.reshape(P, -1, weight.shape[-1]).transpose(1, 2),
                       bias.reshape(P, -1))]  # fmt: skip
        for weight, bias in layers[1:]:
            out.append(augment(weight.reshape(P * K, weight.shape[2], -1).transpose(1, 2),
                               bias.reshape(P * K, -1)))  # fmt: skip
        return out

    def forward(self, obs: Tensor) -> Tensor:
        self._check_obs(obs)
        return self._values(obs)

    def td_update(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        mask = self._check_update(obs, action, target, mask)
        return self.step(obs, action, target, mask)

    def step(self, obs: Tensor, action: Tensor, target: Tensor, mask: Tensor) -> Tensor:
        """One SGD step on the summed loss of the scaled TD errors, over any leading batch
        dims: ``obs [*B, P, D]``, ``action [*B, P]``, ``target``/``mask [*B, P, K]`` (a
        replayed minibatch, or :meth:`td_update`'s one step); ``delta [*B, P, K]``."""
        dtype = self._dtype
        act = torch.where(mask.any(-1), action.to(torch.int64), torch.zeros_like(action))
        weight = mask.to(dtype)
        goal = torch.where(mask, target.to(dtype), torch.zeros((), dtype=dtype))
        layers = [(w.detach().requires_grad_(), b.detach().requires_grad_())
                  for w, b in self._layers()]  # fmt: skip
        with torch.enable_grad():
            q = self._values(obs, layers)  # [*B, P, K, A]
            index = act[..., None, None].expand(*act.shape, self.slots, 1)
            delta = goal - q.gather(-1, index)[..., 0]
            e = delta / self.q_scale
            loss = (functional.smooth_l1_loss(e, torch.zeros_like(e), reduction="none")
                    if self.loss_function == "smooth_l1" else 0.5 * e * e)  # fmt: skip
            # Each slot's loss reads only its own parameters: a masked-out slot's gradient is 0.
            flat = [t for pair in layers for t in pair]
            batch = max(1, weight[..., 0, 0].numel())  # the mean over replayed steps
            grads = torch.autograd.grad((weight * loss).sum() / batch, flat)
        with torch.no_grad():
            for (w, b), (gw, gb) in zip(self._layers(), zip(grads[0::2], grads[1::2])):
                w.sub_(self.lr * gw)
                b.sub_(self.lr * gb)
        delta = delta.detach()
        return torch.where(mask, delta, torch.zeros_like(delta))

    @torch.no_grad()
    def fit_values(self, mask: Tensor, obs: Tensor, values: Tensor) -> None:
        """``Q_k(s, a) ~ values[p, n, a]`` on the states ``obs [N, D]``, for the slots in
        ``mask [P, K]``: each chosen network's output layer becomes the least-squares fit in its
        own last hidden layer (the hidden layers stay as they are: as initialised, or as
        gestation's off-policy updates left them).

        The neural counterpart of :func:`~skillchain_torch.discovery.gestation.
        initialise_option_policies`: a joining option's policy starts as the agent's own
        (``policy_start="top-level"``).

        Example:
            >>> head = MLPOptionQHead(population=1, slots=2, hidden=16, layers=1)
            >>> obs = torch.rand(200, 4, dtype=torch.float64)
            >>> values = torch.zeros(1, 200, 5, dtype=torch.float64)
            >>> values[..., 3] = 10.0                                   # action 3 is the best
            >>> head.fit_values(torch.tensor([[False, True]]), obs, values)
            >>> head(obs[:1].expand(1, 4))[0].argmax(-1).tolist()      # slot 0 untouched: ties
            [0, 3]
        """
        m = check_slot_mask(mask, self.population, self.slots)
        layers = self._layers()
        for p, k in m.nonzero().tolist():  # each network alone: no population effect
            x = obs.to(self._dtype) * 2.0 - 1.0  # as _values: [0, 1] -> [-1, 1]
            for weight, bias in layers[:-1]:  # weight [P, K, out, in]
                x = torch.tanh(affine_rows(x, weight[p, k], bias[p, k]))
            h = torch.cat([x, torch.ones_like(x[:, :1])], dim=-1).to(torch.float64)
            fit = least_squares(h, values[p].to(h) / self.q_scale)  # [H + 1, A]
            weight, bias = layers[-1]  # [P, K, A, H], [P, K, A]
            weight[p, k] = fit[:-1].T.to(weight)
            bias[p, k] = fit[-1].to(bias)

    def slot_tensors(self) -> dict[str, Tensor]:
        return {key: param.data for key, param in self.params.items()}

    @torch.no_grad()
    def reset_slots(self, mask: Tensor) -> None:
        mask = check_slot_mask(mask, self.population, self.slots)
        self.slot_epoch += mask.to(self.slot_epoch)
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
            new.slot_epoch.copy_(self.slot_epoch[index])
            if seeds is None:
                new.rng_counter.copy_(self.rng_counter[index])
        return new
