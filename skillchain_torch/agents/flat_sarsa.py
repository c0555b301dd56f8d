"""``FlatSarsaAgent``: the paper's baseline without options, for a population of agents.

Sarsa (gamma = 1, epsilon = 0.01) with linear function approximation over a Fourier basis of the
4-d observation (paper section 5.1). The library's pieces hold its parameters and, on the torch
path, do its arithmetic, one call each per step:

* :class:`~skillchain_torch.features.FourierBasis`: ``phi(s')``;
* :class:`~skillchain_torch.modules.LinearQHead`: ``Q(s', .)``;
* :func:`~skillchain_torch.policies.epsilon_greedy`: ``a'``, from two uniforms of the agent's
  :class:`~skillchain_torch.rng.CounterRNG` stream;
* :class:`~skillchain_torch.objectives.SarsaUpdate`: ``w[a] += step * (delta * phi(s))``
  toward ``r + gamma Q(s', a')`` (a primitive action lasts one step, ``k = 1``).

The agents still training are compact rows (row i = agent ``index[i]``) of a working
``LinearQHead``, so a step costs what the active agents cost; :meth:`flush` writes them back
into ``q_head``. The uniforms are drawn ahead, 64 decisions at a time: each is a pure function
of the agent's seed and counter, so drawing ahead changes no value.

On the CPU, when the extension is built, the same steps run in C instead
(:mod:`skillchain_torch.backends.sarsa`, ``native=True``, the default there): one pass per
agent row for Q(s', .), the epsilon-greedy rule and the update, with dot products summed in an
order of their own, so the weights agree with the torch path to rounding rather than bit for
bit (the features and the random draws are the same either way).

``tests/agents/test_flat_sarsa.py`` checks the torch path against the library pieces driven by
hand, bit for bit, and the compiled path to 1e-10 with the same decisions.

Episode protocol (driven by the trainer, rows = active agents in ascending id order):
``begin(obs)`` picks the first actions; ``observe(obs, reward)`` learns from a step in which no
episode ended and returns the next actions; ``observe_ends(...)`` does the same when some did
(terminal updates do not bootstrap, truncated ones do; restarted agents decide at their new start
state *after* their update); ``compact(keep)`` drops agents that finished all their episodes.

Example:
    >>> import torch
    >>> from skillchain_torch.trainers import TrainConfig
    >>> agent = FlatSarsaAgent(TrainConfig(runs=2, seed=0, alpha=0.1), native=False)
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
    >>> agent.begin(obs).tolist()  # all Q = 0: ties broken by each agent's stream
    [2, 3]
    >>> agent.observe(obs, torch.tensor([-5.0, -5.0], dtype=torch.float64)).tolist()
    [4, 2]
    >>> agent.flush()
    >>> agent.q_head.weight[:, :, 0].tolist()  # Q(s, a) moved by alpha * (-5) * phi_0 = -0.5
    [[0.0, 0.0, -0.5, 0.0, 0.0], [0.0, 0.0, 0.0, -0.5, 0.0]]
"""

from __future__ import annotations

import math
from functools import partial
from typing import TYPE_CHECKING

import torch
from torch import Tensor, nn

from skillchain_torch.backends.select import check_same_kernels, flat_step
from skillchain_torch.envs.pinball import NUM_ACTIONS
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import SarsaUpdate
from skillchain_torch.policies import NUM_UNIFORMS, EpsilonGreedy, checked_epsilon, epsilon_greedy
from skillchain_torch.rng import CounterRNG

if TYPE_CHECKING:  # the run config is the trainers' (an agent reads only its fields)
    from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["FlatSarsaAgent", "AGENT_STREAM", "BLOCK_DECISIONS"]

AGENT_STREAM = 0  # the decision stream; the env's start stream uses its own salt
BLOCK_DECISIONS = 64  # decisions whose uniforms are drawn ahead per refill
OBS_DIM = 4


class _Work:
    """Working state of the active rows (compact, row i = agent ``index[i]``).

    A plain object: setting attributes of an nn.Module costs microseconds, several times a step.
    """

    __slots__ = ("index", "n", "head", "phi", "action", "available", "one", "never", "base",
                 "j", "uniforms", "gamma")


class FlatSarsaAgent(nn.Module):
    """Population-batched flat Sarsa over primitive actions.

    Args:
        config: the run's :class:`TrainConfig` (``order``/``alpha`` resolved to paper values
            when ``None``); ``config.runs`` is the population P.
        device: torch device (default ``config.device``).
        native: run the per-step arithmetic in C (:mod:`skillchain_torch.backends.sarsa`;
            default: when it is built and the agent is on the CPU). Its Q values and updates
            agree with the torch path to rounding, not bit for bit, so a run's bits depend on
            this choice (it is saved with the agent's state; a checkpoint of the other kind is
            refused). Either way agent p of a population equals the single run with seed
            S + p bit for bit.

    Example:
        >>> from skillchain_torch.trainers import TrainConfig
        >>> agent = FlatSarsaAgent(TrainConfig(runs=2, seed=0))
        >>> agent.q_head.weight.shape
        torch.Size([2, 5, 625])
    """

    def __init__(self, config: TrainConfig, device: torch.device | str | None = None,
                 native: bool | None = None):
        super().__init__()
        cfg = config.resolved()
        device = torch.device(cfg.device if device is None else device)
        # The step's four calls, bound once: this file's torch path, or the compiled step
        # where it applies (backends.select.flat_step).
        self._bind_step(flat_step(native, device, cfg.obs_dim, cfg.num_actions))
        self.config = cfg
        self.population = cfg.runs
        # The environment's sizes (its specs; Pinball's 4 and 5 when not given).
        self.num_actions = NUM_ACTIONS if cfg.num_actions is None else int(cfg.num_actions)
        self.obs_dim = OBS_DIM if cfg.obs_dim is None else int(cfg.obs_dim)
        self.features = FourierBasis(self.obs_dim, cfg.order).to(device)
        self.q_head = LinearQHead(self.features.num_features, self.num_actions, cfg.runs,
                                  device=device)
        self.policy = EpsilonGreedy(cfg.epsilon)
        scale = self.features.step_size_scale() if cfg.scale_step_size else None
        self.update = SarsaUpdate(cfg.alpha, cfg.gamma, step_size_scale=scale).to(device)
        self.rng = CounterRNG.from_seed(cfg.seed, cfg.runs, stream=AGENT_STREAM, device=device)
        w = self._work = _Work()
        # The kernel's gamma: None is 1 without a multiplication (SarsaUpdate skips it too).
        w.gamma = None if cfg.gamma == 1.0 else float(cfg.gamma)
        self._set_active(torch.arange(cfg.runs, device=device))
        w.phi = torch.zeros(cfg.runs, self.features.num_features, dtype=torch.float64,
                            device=device)
        w.action = torch.zeros(cfg.runs, dtype=torch.int64, device=device)

    def _bind_step(self, kernel) -> None:
        """Bind the step's calls to ``kernel`` (a compiled step) or, with ``None``, to this
        file's torch path: the choice is made here, once, never inside the step."""
        self.kernel, self.native = kernel, kernel is not None
        if kernel is None:
            self.q_values, self._row_values = self._torch_values, self._torch_row_values
            self._sarsa_step, self._observe_step = self._torch_sarsa_step, self._torch_observe
        else:
            self.q_values, self._row_values = (partial(kernel.values, self),
                                               partial(kernel.row_values, self))
            self._sarsa_step = partial(kernel.learn, self)
            self._observe_step = partial(kernel.observe, self)

    def set_epsilon(self, epsilon: float) -> None:
        """Explore at ``epsilon`` from the next action on; an annealing schedule
        (``TrainConfig.epsilon_init``) calls it each population step.

            >>> from skillchain_torch.trainers import TrainConfig
            >>> agent = FlatSarsaAgent(TrainConfig(runs=2, seed=0), native=False)
            >>> agent.set_epsilon(0.5); agent.policy.epsilon
            0.5
        """
        self.policy.epsilon = checked_epsilon(epsilon)

    # ------------------------------------------------------------------ pieces
    def featurize(self, obs: Tensor) -> Tensor:
        """``FourierBasis(obs)``: ``[n, 4] -> [n, F]``."""
        return self.features(obs)

    def _torch_values(self, phi: Tensor) -> Tensor:
        """``Q(s, .)`` of every working row: ``phi [n, F] -> [n, D]`` (``q_values``)."""
        return self._work.head(phi)

    def _torch_row_values(self, phi: Tensor, rows: Tensor) -> Tensor:
        """``Q(s, .)`` of the working ``rows`` only, from their features ``phi [n, F]``
        (the other rows' are not read): ``[len(rows), D]``."""
        head = self._work.head
        wanted = torch.zeros(head.population, dtype=torch.bool, device=phi.device)
        wanted[rows] = True
        return head.forward_rows(phi, wanted)[rows]

    def _decide(self, q: Tensor, uniforms: Tensor) -> Tensor:
        """The epsilon-greedy rule over all actions, for ``q [m, D]`` and ``uniforms [m, 2]``.

        ``check=False``: every action is available, and NaN values (diverged weights) are
        reported by :meth:`_refill` with the agents' ids, not here.
        """
        available = self._work.available[: q.shape[0]]
        return epsilon_greedy(q, available, self.policy.epsilon, uniforms, check=False)

    def _learn(self, reward: Tensor, phi1: Tensor, a1: Tensor, q1: Tensor,
               terminated: Tensor | None) -> None:  # fmt: skip
        """One Sarsa step of every working row toward ``r + gamma Q(s', a')`` (no bootstrap
        where ``terminated``); ``q1 = Q(s', .)`` from the weights before the step."""
        q_next = q1.gather(1, a1[:, None])[:, 0]
        self._sarsa_step(reward, phi1, a1, q_next, terminated)

    def _torch_sarsa_step(self, reward: Tensor, phi1: Tensor, a1: Tensor, q_next: Tensor,
                          terminated: Tensor | None) -> None:  # fmt: skip
        w = self._work
        self.update(w.head, w.phi, w.action, reward, w.one, phi1, a1,
                    w.never if terminated is None else terminated, next_value=q_next)

    def _next_slot(self) -> int:
        """Consume one decision's uniforms (2 per active row); its slot in ``uniforms``."""
        w = self._work
        if w.j == BLOCK_DECISIONS:
            self._refill(w.base + NUM_UNIFORMS * BLOCK_DECISIONS)
        w.j += 1
        return w.j - 1

    def _refill(self, base: Tensor) -> None:
        """Draw the next block of uniforms from counters ``base``: ``[n, 64, 2]``."""
        w = self._work
        w.base, w.j = base, 0
        weight = w.head.weight
        # One sum is non-finite if any weight is (a pass over the weights, not three); an
        # overflowing sum of finite weights finds no bad agent and raises nothing.
        if not math.isfinite(float(weight.sum())):
            bad = w.index[~torch.isfinite(weight).flatten(1).all(-1)].tolist()
            if bad:
                raise FloatingPointError(
                    f"agents {bad} have non-finite weights (alpha too large?)")
        stream = CounterRNG(self.rng.seeds[w.index], self.rng.stream, counter=base)
        w.uniforms = stream.uniform(NUM_UNIFORMS * BLOCK_DECISIONS).view(
            w.n, BLOCK_DECISIONS, NUM_UNIFORMS)  # u0, u1 of each decision

    def _counters(self) -> Tensor:
        """Draws consumed so far by the active rows."""
        w = self._work
        return w.base + NUM_UNIFORMS * w.j

    # ------------------------------------------------------------------ protocol
    def begin(self, obs: Tensor) -> Tensor:
        """First decisions of every active agent at its start observation ``[n, 4]``."""
        w = self._work
        w.phi = self.featurize(obs)
        slot = self._next_slot()
        w.action = self._decide(self.q_values(w.phi), w.uniforms[:, slot])
        return w.action

    def observe(self, obs: Tensor, reward: Tensor) -> Tensor:
        """Learn from ``(s, a, r, s')`` for every active row (no episode ended); next actions."""
        w = self._work
        phi1 = self.features(obs)
        slot = self._next_slot()
        a1 = self._observe_step(phi1, reward, slot)
        w.phi, w.action = phi1, a1
        return a1

    def _torch_observe(self, phi1: Tensor, reward: Tensor, slot: int) -> Tensor:
        """The step of every working row without an episode end: its next actions."""
        q1 = self.q_values(phi1)
        a1 = self._decide(q1, self._work.uniforms[:, slot])
        self._learn(reward, phi1, a1, q1, None)
        return a1

    def observe_ends(
        self,
        obs: Tensor,
        reward: Tensor,
        terminated: Tensor,
        truncated: Tensor,
        restart_rows: Tensor,
        start_obs: Tensor | None,
    ) -> Tensor:
        """Like :meth:`observe` when some episodes ended.

        Args:
            obs, reward: the step's next observations ``[n, 4]`` and rewards ``[n]``.
            terminated: rows that reached the goal (no bootstrap).
            truncated: rows cut by the step limit (bootstrap from ``Q(s', a')`` with ``a'``
                drawn at ``s'``).
            restart_rows: rows that begin a new episode at ``start_obs`` ``[m, 4]``; their
                first decision is made after this step's update. Ended rows not listed here
                have finished training and are dropped by the next :meth:`compact`.
        """
        w = self._work
        phi1 = self.features(obs)
        q1 = self.q_values(phi1)
        slot = self._next_slot()
        uniforms = w.uniforms[:, slot]
        a1 = self._decide(q1, uniforms)
        self._learn(reward, phi1, a1, q1, terminated)
        if restart_rows.numel() > 0:
            phi1, a1 = phi1.clone(), a1.clone()
            phi1[restart_rows] = self.features(start_obs)
            q_start = self._row_values(phi1, restart_rows)
            # A terminated row's next decision is its start decision: it takes this step's
            # uniforms (its decision at s' above is discarded). A truncated row already used
            # them at s', so its start decision draws two more.
            a_start = self._decide(q_start, uniforms[restart_rows])
            extra = truncated[restart_rows]
            if bool(extra.any()):
                counters = self._counters()
                rows = restart_rows[extra]
                stream = CounterRNG(self.rng.seeds[w.index[rows]], self.rng.stream,
                                    counter=counters[rows])
                a_start[extra] = self._decide(q_start[extra], stream.uniform(NUM_UNIFORMS))
                counters[rows] += NUM_UNIFORMS
                self._refill(counters)
            a1[restart_rows] = a_start
        w.phi, w.action = phi1, a1
        return a1

    # ------------------------------------------------------------------ active set
    @property
    def index(self) -> Tensor:
        """Ids of the active agents, ascending ``[n]`` (row i of the working state)."""
        return self._work.index

    @property
    def actions(self) -> Tensor:
        """The current action of each active row ``[n]``."""
        return self._work.action

    def working_weights(self, rows: Tensor) -> Tensor:
        """The current weights of the active ``rows``, ``[len(rows), D, F]``, without a
        :meth:`flush` (the trainer's divergence check reads them at episode ends)."""
        return self._work.head.weight.index_select(0, rows)

    def _set_active(self, index: Tensor, base: Tensor | None = None) -> None:
        weight = self.q_head.weight  # [P, D, F]
        w = self._work
        n, dev = int(index.numel()), weight.device
        w.index, w.n = index, n
        w.head = LinearQHead(self.q_head.num_features, self.num_actions, n, dtype=weight.dtype,
                             device=dev)  # fmt: skip
        w.head.weight = weight[index]  # a contiguous copy of the rows (the kernels need one)
        w.available = torch.ones(n, self.num_actions, dtype=torch.bool, device=dev)
        w.one = torch.ones(n, dtype=torch.int64, device=dev)  # k = 1: primitive actions
        w.never = torch.zeros(n, dtype=torch.bool, device=dev)
        self._refill(self.rng.counter[index].clone() if base is None else base)

    def flush(self) -> None:
        """Write the working rows (weights, stream counters) back into ``q_head`` and ``rng``."""
        w = self._work
        self.q_head.weight[w.index] = w.head.weight
        counter = self.rng.counter.clone()
        counter[w.index] = self._counters()
        self.rng.counter = counter

    def compact(self, keep: Tensor) -> None:
        """Keep the rows where ``keep`` (bool ``[n]``) is True; the others stop for good."""
        self.flush()
        w = self._work
        rows = keep.nonzero().flatten()
        counters = self._counters()[rows]
        phi, action = w.phi[rows], w.action[rows]
        self._set_active(w.index[rows], counters)
        w.phi, w.action = phi, action

    # ------------------------------------------------------------------ state
    def state_dict(self, *args, **kwargs):
        """Weights, streams, and the active agents' current features and decisions."""
        self.flush()
        w = self._work
        population, dev = self.population, self.q_head.weight.device
        action = torch.full((population,), -1, dtype=torch.int64, device=dev)
        action[w.index] = w.action
        phi = torch.zeros(population, self.features.num_features, dtype=torch.float64, device=dev)
        phi[w.index] = w.phi
        return {
            "q_head": self.q_head.state_dict(),
            "rng": self.rng.state_dict(),
            "index": self.index.clone(),
            "action": action,
            "phi": phi,
            "native": self.native,
        }

    def load_state_dict(self, state, strict: bool = True, assign: bool = False):
        dev = self.q_head.weight.device
        check_same_kernels(state, self.native)
        self.q_head.load_state_dict(state["q_head"])
        self.rng.load_state_dict(state["rng"])
        self.rng.to(dev)
        index = state["index"].to(dev)
        self._set_active(index)
        w = self._work
        w.phi = state["phi"].to(dev)[index].clone()
        w.action = state["action"].to(dev)[index].clone()

    def extra_repr(self) -> str:
        cfg = self.config
        return (f"population={self.population}, order={cfg.order}, alpha={cfg.alpha}, "
                f"gamma={cfg.gamma}, epsilon={cfg.epsilon}, "
                f"active={int(self._work.index.numel())}, native={self.native}")
