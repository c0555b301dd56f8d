"""``FlatSarsaAgent``: the paper's baseline without options, for a population of agents.

Sarsa (gamma = 1, epsilon = 0.01) with linear function approximation over a Fourier basis of the
4-d observation (paper section 5.1). The agent is built from the library's pieces --
:class:`~skillchain_torch.features.FourierBasis`, :class:`~skillchain_torch.modules.LinearQHead`,
:class:`~skillchain_torch.policies.EpsilonGreedy`, :class:`~skillchain_torch.objectives.SarsaUpdate`
and one :class:`~skillchain_torch.rng.CounterRNG` stream per agent -- which hold its parameters and
state. The per-step hot path (``observe``) evaluates the *same* arithmetic in fewer tensor
operations (:mod:`.kernels`), on a compact working copy of the agents still training:

* the working weights are action-major, ``[D, n, F]``, so ``Q = sum_f w * phi`` multiplies
  contiguous blocks (the sums are the same row sums LinearQHead computes);
* uniforms are drawn ahead in blocks from each agent's counter (values depend only on the seed
  and the counter), and the epsilon-greedy choice for each of them is tabulated per possible
  greedy set (:func:`~.kernels.decision_table`);
* the update ``delta = (r + gamma Q(s', a')) - Q(s, a)``, ``w[a] += step * (delta * phi)`` keeps
  :class:`SarsaUpdate`'s expression order.

On the CPU, when the extension is built, the same steps run in C instead (:mod:`.native_sarsa`,
``native=True``, the default there): one pass per agent row for Q(s', .), the tabulated choice
and the update, with dot products summed in an order of its own, so the weights agree with the
library pieces to rounding rather than bit for bit (the features are FourierBasis's either way).

``tests/trainers/test_flat.py`` checks the torch path against the library pieces bit for bit,
and the compiled path to 1e-10 with the same decisions.

Episode protocol (driven by the trainer, rows = active agents in ascending id order):
``begin(obs)`` picks the first actions; ``observe(obs, reward)`` learns from a step in which no
episode ended and returns the next actions; ``observe_ends(...)`` does the same when some did
(terminal updates do not bootstrap, truncated ones do; restarted agents decide at their new start
state *after* their update); ``compact(keep)`` drops agents that finished all their episodes.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from skillchain_torch.backends.native import check_same_kernels
from skillchain_torch.backends.select import compiled
from skillchain_torch.envs.pinball import NUM_ACTIONS
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import SarsaUpdate
from skillchain_torch.policies import NUM_UNIFORMS, EpsilonGreedy
from skillchain_torch.rng import CounterRNG

from . import native_sarsa
from .config import TrainConfig
from .kernels import candidate_codes, decide, decision_table

__all__ = ["FlatSarsaAgent", "AGENT_STREAM", "BLOCK_DECISIONS"]

AGENT_STREAM = 0  # the decision stream; the env's start stream uses its own salt
BLOCK_DECISIONS = 64  # decisions whose uniforms are drawn (and tabulated) ahead per refill
OBS_DIM = 4
CHUNK_ROWS = 16  # from this many active rows on, Q is formed one action at a time


class _Work:
    """Working state of the active rows (compact, row i = agent ``index[i]``)."""

    __slots__ = ("index", "n", "w", "w_flat", "arange", "prod", "phi", "action", "rows", "base",
                 "j", "table", "table_rows", "explore", "u1", "step_size", "gamma", "epsilon",
                 "gamma_float")


class FlatSarsaAgent(nn.Module):
    """Population-batched flat Sarsa over primitive actions.

    Args:
        config: the run's :class:`TrainConfig` (``order``/``alpha`` resolved to paper values
            when ``None``); ``config.runs`` is the population P.
        device: torch device (default ``config.device``).
        native: run the per-step arithmetic in C (:mod:`.native_sarsa`; default: when it is
            built and the agent is on the CPU). Its Q values and updates agree with the torch
            path to rounding, not bit for bit, so a run's bits depend on this choice (it is
            saved with the agent's state; a checkpoint of the other kind is refused). Either
            way agent p of a population equals the single run with seed S + p bit for bit.

    Example:
        >>> agent = FlatSarsaAgent(TrainConfig(runs=2, seed=0))
        >>> agent.q_head.weight.shape
        torch.Size([2, 5, 625])
        >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
        >>> agent.begin(obs).tolist()  # all Q = 0: ties broken by each agent's stream
        [2, 3]
    """

    def __init__(self, config: TrainConfig, device: torch.device | str | None = None,
                 native: bool | None = None):
        super().__init__()
        cfg = config.resolved()
        device = torch.device(cfg.device if device is None else device)
        self.native = compiled(native, {
            "the compiled kernels (built)": native_sarsa.AVAILABLE,
            f"the CPU (got {device})": device.type == "cpu",
            "Pinball's 4-d observation and 5 actions":
                cfg.obs_dim in (None, OBS_DIM) and cfg.num_actions in (None, NUM_ACTIONS),
        })
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
        self._powers = (2 ** torch.arange(self.num_actions, device=device))[:, None]  # [D, 1]
        # The hot path's state lives in a plain object: setting attributes of an nn.Module
        # costs microseconds, several times per step.
        w = self._work = _Work()
        w.step_size = self.update.step_size
        w.epsilon = torch.tensor(cfg.epsilon, dtype=torch.float64, device=device)
        w.gamma = None if cfg.gamma == 1.0 else torch.tensor(cfg.gamma, dtype=torch.float64,
                                                             device=device)
        w.gamma_float = None if cfg.gamma == 1.0 else float(cfg.gamma)
        self._set_active(torch.arange(cfg.runs, device=device))
        w.phi = torch.zeros(cfg.runs, self.features.num_features, dtype=torch.float64,
                            device=device)
        self._set_action(torch.zeros(cfg.runs, dtype=torch.int64, device=device))

    # ------------------------------------------------------------------ pieces
    def featurize(self, obs: Tensor) -> Tensor:
        """``FourierBasis(obs)``: ``[n, 4] -> [n, F]``."""
        return self.features(obs)

    def q_values(self, phi: Tensor, rows: Tensor | None = None) -> Tensor:
        """``LinearQHead.forward`` of the working rows (all, or ``rows``), action-major
        ``[D, n]``: ``q[d, i] = sum_f w[d, i, f] * phi[i, f]``.

        For many rows the products are formed one action at a time, so each block stays in
        cache between the multiply and the sum (the same row sums, a third of the memory
        traffic).
        """
        w = self._work
        if self.native:
            return native_sarsa.linear_q(w.w, phi, rows)
        if rows is not None:
            return (w.w[:, rows] * phi[None]).sum(-1)
        if w.n < CHUNK_ROWS:
            return torch.mul(w.w, phi[None], out=w.prod).sum(-1)
        q = torch.empty(self.num_actions, w.n, dtype=phi.dtype, device=phi.device)
        for d in range(self.num_actions):
            torch.sum(torch.mul(w.w[d], phi, out=w.prod), -1, out=q[d])
        return q

    @staticmethod
    def decide(q: Tensor, explore: Tensor, u1: Tensor) -> Tensor:
        """Epsilon-greedy of ``q [n, D]`` from explicit uniforms (see :func:`.kernels.decide`)."""
        return decide(q, explore, u1)

    def _decide_slot(self, q: Tensor, rows: Tensor | None = None) -> Tensor:
        """This step's epsilon-greedy choice from the tabulated slot ``j - 1``: ``[n]``."""
        w = self._work
        code = candidate_codes(q, self._powers)
        table = w.table[:, w.j - 1]  # [n, 2^D]
        if rows is None:
            return table.take(w.table_rows + code)
        return table[rows].take(w.table_rows[: rows.numel()] + code)

    def _next_slot(self) -> None:
        """Consume one decision's uniforms (2 per active row)."""
        w = self._work
        if w.j == BLOCK_DECISIONS:
            self._refill(w.base + NUM_UNIFORMS * BLOCK_DECISIONS)
        w.j += 1

    def _refill(self, base: Tensor) -> None:
        """Draw the next block of uniforms from counters ``base`` and tabulate the decisions."""
        w = self._work
        w.base, w.j = base, 0
        # One sum is non-finite if any weight is (a pass over the weights, not three); an
        # overflowing sum of finite weights finds no bad agent and raises nothing.
        if not math.isfinite(float(w.w.sum())):
            bad = w.index[~torch.isfinite(w.w).flatten(2).all(-1).all(0)].tolist()
            if bad:
                raise FloatingPointError(
                    f"agents {bad} have non-finite weights (alpha too large?)")
        stream = CounterRNG(self.rng.seeds[w.index], self.rng.stream, counter=base)
        block = stream.uniform(NUM_UNIFORMS * BLOCK_DECISIONS)  # u0, u1, u0, u1, ...
        w.explore = block[:, 0::2] < w.epsilon
        w.u1 = block[:, 1::2]
        w.table = decision_table(w.explore, w.u1, self.num_actions)

    def _counters(self) -> Tensor:
        """Draws consumed so far by the active rows."""
        w = self._work
        return w.base + NUM_UNIFORMS * w.j

    def _set_action(self, action: Tensor) -> None:
        w = self._work
        w.action = action
        w.rows = torch.add(w.arange, action, alpha=w.n)  # row of (action, agent) in w_flat

    # ------------------------------------------------------------------ protocol
    def begin(self, obs: Tensor) -> Tensor:
        """First decisions of every active agent at its start observation ``[n, 4]``."""
        w = self._work
        w.phi = self.featurize(obs)
        self._next_slot()
        self._set_action(self._decide_slot(self.q_values(w.phi)))
        return w.action

    def observe(self, obs: Tensor, reward: Tensor) -> Tensor:
        """Learn from ``(s, a, r, s')`` for every active row (no episode ended); next actions."""
        w = self._work
        if self.native:  # the whole step per agent row in C
            phi1 = self.features(obs)
            self._next_slot()
            # The C code reads raw memory: rewards as contiguous float64 (a no-op from the
            # stepper; the Python-float stepper hands a strided column).
            reward = reward.to(torch.float64).contiguous()
            a1 = native_sarsa.sarsa_observe(w.w, w.phi, phi1, w.action, reward, w.table,
                                            w.j - 1, w.step_size, w.gamma_float)
            w.phi, w.action, w.rows = phi1, a1, None  # rows: only the torch path reads them
            return a1
        phi1 = self.features(obs)
        q1 = self.q_values(phi1)
        self._next_slot()
        a1 = self._decide_slot(q1)
        rows1 = torch.add(w.arange, a1, alpha=w.n)
        self._learn(reward, q1.take(rows1), None)
        w.phi, w.action, w.rows = phi1, a1, rows1
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
        self._next_slot()
        a1 = self._decide_slot(q1)
        self._learn(reward, q1.take(torch.add(w.arange, a1, alpha=w.n)), terminated)
        if restart_rows.numel() > 0:
            # A terminated row's next decision is its start decision: it takes this step's
            # uniforms (its decision at s' above is discarded). A truncated row already used
            # them at s', so its start decision draws two more.
            phi_start = self.features(start_obs)
            q_start = self.q_values(phi_start, restart_rows)
            a_start = self._decide_slot(q_start, restart_rows)
            extra = truncated[restart_rows]
            if bool(extra.any()):
                counters = self._counters()
                rows = restart_rows[extra]
                stream = CounterRNG(self.rng.seeds[w.index[rows]], self.rng.stream,
                                    counter=counters[rows])
                u = stream.uniform(NUM_UNIFORMS)
                a_start[extra] = decide(q_start.T[extra], u[:, 0] < w.epsilon, u[:, 1])
                counters[rows] += NUM_UNIFORMS
                self._refill(counters)
            phi1, a1 = phi1.clone(), a1.clone()
            phi1[restart_rows] = phi_start
            a1[restart_rows] = a_start
        w.phi = phi1
        self._set_action(a1)
        return a1

    def _learn(self, reward: Tensor, q_next: Tensor, terminated: Tensor | None) -> None:
        """One Sarsa step per active row, as ``SarsaUpdate`` computes it."""
        w = self._work
        if self.native:
            terminated = None if terminated is None else terminated.contiguous()
            reward = reward.to(torch.float64).contiguous()
            native_sarsa.sarsa_learn(w.w, w.phi, w.action, reward, q_next,
                                     terminated, w.step_size, w.gamma_float)
            return
        w_sa = w.w_flat.index_select(0, w.rows)
        q_sa = (w_sa * w.phi).sum(-1)
        bootstrap = q_next if w.gamma is None else w.gamma * q_next  # 1.0 * x == x
        if terminated is not None:
            bootstrap = torch.where(terminated, torch.zeros_like(bootstrap), bootstrap)
        delta = (reward + bootstrap) - q_sa
        w_sa += w.step_size * (delta[:, None] * w.phi)
        w.w_flat.index_copy_(0, w.rows, w_sa)

    # ------------------------------------------------------------------ active set
    @property
    def index(self) -> Tensor:
        """Ids of the active agents, ascending ``[n]`` (row i of the working state)."""
        return self._work.index

    @property
    def actions(self) -> Tensor:
        """The current action of each active row ``[n]``."""
        return self._work.action

    def _set_active(self, index: Tensor, base: Tensor | None = None) -> None:
        weight = self.q_head.weight  # [P, D, F]
        w = self._work
        w.index, w.n = index, int(index.numel())
        w.w = weight[index].transpose(0, 1).contiguous()  # [D, n, F]
        w.w_flat = w.w.view(self.num_actions * w.n, weight.shape[-1])
        w.arange = torch.arange(w.n, device=weight.device)
        w.table_rows = w.arange * (1 << self.num_actions)
        w.prod = torch.empty_like(w.w if w.n < CHUNK_ROWS else w.w[0])
        self._refill(self.rng.counter[index].clone() if base is None else base)

    def flush(self) -> None:
        """Write the working rows (weights, stream counters) back into ``q_head`` and ``rng``."""
        w = self._work
        self.q_head.weight[w.index] = w.w.transpose(0, 1)
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
        w.phi = phi
        self._set_action(action)

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
        self._set_action(state["action"].to(dev)[index].clone())

    def extra_repr(self) -> str:
        cfg = self.config
        return (f"population={self.population}, order={cfg.order}, alpha={cfg.alpha}, "
                f"gamma={cfg.gamma}, epsilon={cfg.epsilon}, "
                f"active={int(self._work.index.numel())}, native={self.native}")
