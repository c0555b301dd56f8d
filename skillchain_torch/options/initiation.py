"""Initiation-set classifiers: logistic regression per option slot (paper section 5.1).

Each slot's initiation set is a logistic regression on 2nd-order polynomial features of the
observation (15 features), initialised to be true everywhere, trained with learning rate 0.1 and
100 sweeps each time new data arrives; once learned it is further constrained to points within
Euclidean distance 0.1 of a positive example.

Example:
    >>> import torch
    >>> clf = InitiationClassifier(population=1, slots=2, capacity=64)
    >>> far = torch.tensor([[0.9, 0.5, 0.5, 0.5]], dtype=torch.float64)
    >>> clf.contains(far).tolist()                       # no data yet: true everywhere
    [[True, True]]
    >>> x = torch.rand(40, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    >>> clf.add_examples(0, 0, x, x[:, 0] < 0.5).tolist()
    [[True, False]]
    >>> _ = clf.fit()                                    # 100 sweeps for the slots with new data
    >>> clf.contains(far).tolist(), clf.sweeps_done.tolist()
    ([[False, True]], [[100, 0]])
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn

from skillchain_torch.backends.select import initiation_kernel
from skillchain_torch.features import PolynomialFeatures
from skillchain_torch.invariant import rowwise_dot, rowwise_sum
from skillchain_torch.options import initiation_fit
from skillchain_torch.options.examples import REPLACEMENTS, failure_place, store_places
from skillchain_torch.options.logistic import logistic_sweeps
from skillchain_torch.options.nearby import within_any
from skillchain_torch.options.q_head import _DTYPES, OBS_DIM, dtype_name
from skillchain_torch.options.status import agent_index, agent_seeds, check_slot_mask, slot_mask

_POINTS_CHUNK = 8192  # points per membership evaluation (bounds the [N, M] distance matrix)


class InitiationClassifier(nn.Module):
    """Population-batched logistic-regression initiation sets with bounded example stores.

    Args:
        population: P agents; slots: K option slots per agent.
        degree: polynomial degree of the features (paper: 2, 15 features for the 4-d obs).
        lr: learning rate eta (paper: 0.1).
        sweeps: gradient sweeps per fit, i.e. per batch of new data (paper: 100).
        capacity: C, the most examples stored per slot (memory ``[P, K, C, 4]``).
        distance: radius of the post-learning constraint (paper: 0.1), Euclidean in the 4-d
            observation ``(x, y, (xdot+1)/2, (ydot+1)/2)`` the classifier sees, so a velocity
            difference counts half (``distance_dims`` restricts it, e.g. ``(0, 1)`` for position).
        replacement: ``"reservoir"`` (default; the ``n``-th example replaces a uniformly drawn
            stored one with probability ``C / (n + 1)``) or ``"ring"`` (the newest C).
        keep_negatives: once a slot's store is full, a new positive that would replace a stored
            *negative* is dropped instead. A success adds up to 250 positives and a failure one
            negative, so a plain reservoir soon holds one or two failures (measured: 499
            positives and 1 negative after 40 episodes) and the set cannot shrink where the
            option fails; the paper's classifier sees every example.
        store_failures: a full store never rejects a *negative* (it replaces a positive,
            :func:`~.examples.failure_place`); a reservoir keeps about 2% late in a run.
        constrain_nearest: the constraint also asks that no stored negative be nearer than
            the nearest positive ("their start states were then removed from the set").
        balanced: weight the two classes equally in the loss (scikit-learn's
            ``class_weight="balanced"``): unweighted, a success's 250 positives outvote the
            single negative of each failure and the set stays wide where the option fails.
        initial_bias: the intercept a slot starts (and restarts) from. "Initialised to be true
            everywhere" is read two ways: 0 (default) with an untrained slot counting as true
            everywhere, so the first fit starts from zero and a lone failure empties the set;
            or a positive value, so the set starts true through its weights and failures
            carve regions out of it.
        centered: features of ``2 s - 1`` (in [-1, 1]) instead of ``s``: a negative example
            then lowers the logit less far from it.
        seed: int (agent p uses ``seed + p``) or ``LongTensor [P]``: the reservoir's draws are a
            hash of (agent seed, slot, slot generation, example index), independent of P.

    Parameters ``weight [P, K, F]`` and ``bias [P, K]`` read as ``nn.Linear(F, 1)`` per slot;
    ``P(s in I_k) = sigmoid(weight . phi(s) + bias)`` and membership is ``logit > 0``. They are
    trained in closed form (no autograd): a sweep is one full-batch gradient step on the mean
    log-loss over the slot's stored examples, ``w -= lr * mean((sigmoid(z) - y) * phi)``, so a
    fit costs at most ``sweeps * C * F`` per slot whatever the amount of data seen (bounded
    time; about 0.4 s for 100 slots with full stores of 500 on one CPU thread), less for slots
    holding few examples (:meth:`fit_length`). The features include the constant 1, so its
    weight and ``bias`` both act as the intercept, as ``nn.Linear`` over ``PolynomialFeatures``
    would. With a cap the distance constraint anchors on the *stored*
    positives (a uniform subsample under ``"reservoir"``), not on every positive ever seen.
    All maths is elementwise, :mod:`~skillchain_torch.invariant` reductions or pairwise
    ``cdist`` (each pair on its own), so agent p's numbers are bit-identical alone or in a
    population.

    Buffers (``[P, K]`` unless noted): ``examples [P, K, C, 4]``, ``labels [P, K, C]`` (bool),
    ``count`` (stored), ``seen`` (ever added), ``generation`` (resets), ``sweeps_done``,
    ``trained`` (fitted at least once; untrained slots contain everything), ``constrained``
    (distance constraint on), ``dirty`` (data added since the last fit), ``seeds [P]``.

    **Your own model.** A subclass that overrides :meth:`logit` (``obs [P, *B, D] ->
    [P, *B, K]``, e.g. through an ``nn.Module`` of its own) is honoured everywhere: membership
    runs its logit on every path (the compiled one serves only this exact class), :meth:`fit`
    trains its ``requires_grad`` parameters by :meth:`make_optimizer` (SGD at ``lr``, default)
    on the same stores and loss, the convergence test compares its logits on fixed probe
    points (:meth:`snapshot`), images use it, and :meth:`OptionBank.load` rebuilds it once it is
    registered (:func:`~skillchain_torch.options.register_classifier`; :mod:`.initiation_fit`).
    """

    def __init__(
        self,
        population: int,
        slots: int,
        degree: int = 2,
        lr: float = 0.1,
        sweeps: int = 100,
        capacity: int = 500,
        distance: float = 0.1,
        distance_dims: tuple[int, ...] | list[int] | None = None,
        replacement: str = "reservoir",
        keep_negatives: bool = False,
        store_failures: bool = False,
        constrain_nearest: bool = False,
        balanced: bool = False,
        initial_bias: float = 0.0,
        centered: bool = False,
        seed: int | Tensor = 0,
        dtype: torch.dtype | str = torch.float64,
        device: torch.device | str | None = None,
        obs_dim: int = OBS_DIM,
    ):
        super().__init__()
        dtype = _DTYPES[dtype] if isinstance(dtype, str) else dtype
        if population < 1 or slots < 1 or capacity < 1 or sweeps < 0:
            raise ValueError("need population, slots, capacity >= 1 and sweeps >= 0")
        if replacement not in REPLACEMENTS:
            raise ValueError(f"replacement must be one of {REPLACEMENTS}, got {replacement!r}")
        dims = tuple(range(obs_dim)) if distance_dims is None else tuple(distance_dims)
        if not dims or any(d < 0 or d >= obs_dim for d in dims):
            raise ValueError(f"distance_dims must be indices of the {obs_dim}-d observation, "
                             f"got {dims}")  # fmt: skip
        self.population, self.slots, self.capacity = population, slots, capacity
        self.obs_dim = int(obs_dim)
        self.lr, self.sweeps, self.distance = float(lr), int(sweeps), float(distance)
        self.distance_dims, self.replacement = dims, replacement
        self.balanced, self.keep_negatives = bool(balanced), bool(keep_negatives)
        self.store_failures, self.constrain_nearest = bool(store_failures), bool(constrain_nearest)
        self.config: dict[str, Any] = dict(
            population=population, slots=slots, degree=degree, lr=self.lr, sweeps=self.sweeps,
            capacity=capacity, distance=self.distance, distance_dims=list(dims),
            replacement=replacement, keep_negatives=self.keep_negatives, balanced=self.balanced,
            initial_bias=float(initial_bias), centered=bool(centered), dtype=dtype_name(dtype),
        )  # fmt: skip
        for name in ("store_failures", "constrain_nearest"):  # (older files: as they were)
            if getattr(self, name):
                self.config[name] = True
        if self.obs_dim != OBS_DIM:  # (Pinball's files keep their config as it was)
            self.config["obs_dim"] = self.obs_dim
        self.initial_bias, self.centered = float(initial_bias), bool(centered)
        self.features = PolynomialFeatures(self.obs_dim, degree, dtype=dtype).to(device)
        self.num_features = self.features.num_features
        pk = (population, slots)
        zeros = torch.zeros
        self.weight = nn.Parameter(zeros(*pk, self.num_features, dtype=dtype, device=device),
                                   requires_grad=False)  # fmt: skip
        self.bias = nn.Parameter(torch.full(pk, self.initial_bias, dtype=dtype, device=device),
                                 requires_grad=False)  # fmt: skip
        self.register_buffer("examples", zeros(*pk, capacity, self.obs_dim, dtype=dtype,
                                               device=device))  # fmt: skip
        self.register_buffer("labels", zeros(*pk, capacity, dtype=torch.bool, device=device))
        for name in ("count", "seen", "generation", "sweeps_done"):
            self.register_buffer(name, zeros(pk, dtype=torch.int64, device=device))
        for name in ("trained", "constrained", "dirty"):
            self.register_buffer(name, zeros(pk, dtype=torch.bool, device=device))
        self.register_buffer("seeds", agent_seeds(seed, population).to(device))
        # The compiled memberships, fits and stores, or None (this file's torch path): chosen
        # once, by backends.select.initiation_kernel, when the agent that owns the set is built.
        self._kernel = None

    @property
    def native(self) -> bool:
        """Whether the compiled kernel runs this set's memberships, fits and stores."""
        return self._kernel is not None

    def set_native(self, native: bool | None = None) -> bool:
        """Take the compiled kernel (:func:`~skillchain_torch.backends.select.initiation_kernel`)
        or the torch path; ``None``: the kernel where it is built, the classifier is exactly
        this class (a subclass may change any rule, which C would not run) and it is on the
        CPU in float64. The kernel's sums run in an order of their own (rounding-level
        differences from the torch path). Returns the choice; ``True`` where it cannot apply
        raises ``ValueError`` naming why.

        Example:
            >>> clf = InitiationClassifier(population=1, slots=2, capacity=8)
            >>> clf.set_native(False), clf.native
            (False, False)
        """
        self._kernel = initiation_kernel(self, native)
        return self.native

    def _apply(self, fn, *args, **kwargs):
        # Moved off the CPU or out of float64: the compiled path no longer applies.
        out = super()._apply(fn, *args, **kwargs)
        if self._kernel is not None and (self.weight.device.type != "cpu"
                                        or self.weight.dtype != torch.float64):  # fmt: skip
            self._kernel = None
        return out

    # ----------------------------------------------------------------------------- membership
    def _check_obs(self, obs: Tensor) -> Tensor:
        if obs.shape[0] != self.population or obs.shape[-1] != self.obs_dim:
            raise ValueError(f"obs must be [P={self.population}, ..., {self.obs_dim}], got "
                             f"{tuple(obs.shape)}")  # fmt: skip
        w = self.weight
        if obs.dtype == w.dtype and obs.device == w.device:  # every step: skip a no-op .to
            return obs
        return obs.to(device=w.device, dtype=w.dtype)

    def phi(self, obs: Tensor) -> Tensor:
        """The classifier's features of observations ``[..., 4]`` (centred if ``centered``)."""
        return self.features(2.0 * obs - 1.0 if self.centered else obs)

    def logit(self, obs: Tensor) -> Tensor:
        """``weight . phi(s) + bias`` for every slot: ``obs [P, *B, D] -> [P, *B, K]``
        (agent p's states only meet agent p's weights). Override it to use your own model."""
        phi = self.phi(self._check_obs(obs))
        between = (1,) * (phi.ndim - 2)  # the batch dims *B
        weight = self.weight.view(self.population, *between, self.slots, -1)
        bias = self.bias.view(self.population, *between, self.slots)
        return rowwise_dot(weight, phi[..., None, :]) + bias

    def builtin_model(self) -> bool:
        """Whether the set is this class's logistic model (:meth:`logit` and :meth:`phi` not
        overridden): it is fitted in closed form on ``weight``/``bias``; otherwise
        :mod:`.initiation_fit` fits and compares the subclass's own model."""
        cls = type(self)
        return cls.logit is InitiationClassifier.logit and cls.phi is InitiationClassifier.phi

    def probability(self, obs: Tensor) -> Tensor:
        """``sigmoid(logit)`` written as ``1 / (1 + exp(-z))`` (layout-invariant)."""
        return 1.0 / (1.0 + torch.exp(-self.logit(obs)))

    def contains(self, obs: Tensor) -> Tensor:
        """Initiation-set membership ``[P, K]``: true everywhere for an untrained slot, else
        ``logit > 0`` (``sigmoid > 1/2``), and near a positive example for constrained slots."""
        if self._kernel is not None:
            return self._kernel.contains(self, self._check_obs(obs))
        member = (self.logit(obs) > 0) | ~self.trained
        # The distance test (C stored examples per slot) only where the logit said yes.
        check = self.constrained & member
        if bool(check.any()):
            near = self.near_positive(obs, check)
            member = member & (near | ~self.constrained)
        return member

    def contains_points(self, agent: int, slot: int, obs: Tensor) -> Tensor:
        """Membership ``BoolTensor [N]`` of many observations ``[N, 4]`` in one slot.

        The rule of :meth:`contains` (which takes one observation per agent) for drawing and
        measuring a set: true everywhere for an untrained slot, else ``logit > 0``, and within
        ``distance`` (in ``distance_dims``) of a stored positive example for constrained slots.
        """
        p, k = int(agent), int(slot)
        w, b = self.weight[p, k], self.bias[p, k]
        trained, constrained = bool(self.trained[p, k]), bool(self.constrained[p, k])
        out = []
        for chunk in obs.to(device=w.device, dtype=w.dtype).split(_POINTS_CHUNK):
            if not trained:  # true everywhere, but for the constraint (as contains)
                member = torch.ones(chunk.shape[0], dtype=torch.bool, device=w.device)
            elif self.builtin_model():
                member = (rowwise_dot(self.phi(chunk), w[None, :]) + b) > 0
            else:  # the subclass's own model, through its logit
                member = initiation_fit.points_logit(self, p, k, chunk) > 0
            out.append(self.near_points(p, k, chunk, member) if constrained else member)
        return torch.cat(out) if out else torch.zeros(0, dtype=torch.bool, device=w.device)

    # ----------------------------------------------------------------------------- fitting
    @torch.no_grad()
    def fit(self, mask: Tensor | None = None) -> Tensor:
        """Run ``sweeps`` gradient steps on each slot in ``mask`` (default: ``dirty``) that holds
        data; others are untouched. Returns the ``[P, K]`` mask of slots fitted.

        A slot's sweeps run over its first :meth:`fit_length` stored examples (the rest are
        empty), so a slot with a few examples costs a few, and the length depends on the slot's
        own count only: its numbers are the same whatever else is fitted with it.
        """
        mask = self.dirty if mask is None else check_slot_mask(mask, self.population, self.slots)
        if self._kernel is not None:  # every slot in one compiled pass
            return self._kernel.fit(self, mask)
        mask = mask.to(self.weight.device) & (self.count > 0)
        where = mask.nonzero()
        if where.shape[0] > 0:
            pi, ki = where[:, 0], where[:, 1]
            lengths = self.fit_length(self.count[pi, ki])
            if self.builtin_model():
                for length in torch.unique(lengths).tolist():
                    group = lengths == length
                    self._fit_slots(pi[group], ki[group], int(length))
            else:  # the subclass's own model, by its optimizer
                with torch.enable_grad():
                    initiation_fit.gradient_fit(self, mask, int(lengths.max()))
            self.sweeps_done[pi, ki] += self.sweeps
            self.trained[pi, ki] = True
        self.dirty &= ~mask
        return mask

    def fit_length(self, count: Tensor) -> Tensor:
        """Examples a fit runs over for slots holding ``count``: the next power of two of at
        least 8, at most the capacity."""
        # log2 and exp2 are exact on powers of two, so ceil lands on the right one.
        exponent = torch.ceil(torch.log2(count.clamp(min=8).to(torch.float64)))
        return torch.exp2(exponent).to(count.dtype).clamp(max=self.capacity)

    def _fit_slots(self, pi: Tensor, ki: Tensor, length: int) -> None:
        """``sweeps`` gradient steps (:func:`logistic_sweeps`) on slots ``(pi, ki)`` over their
        first ``length`` stored places."""
        count = self.count[pi, ki]
        params = logistic_sweeps(
            self.phi(self.examples[pi, ki, :length]),
            self.labels[pi, ki, :length],
            torch.arange(length, device=count.device) < count[:, None],
            torch.cat([self.weight[pi, ki], self.bias[pi, ki, None]], dim=-1),
            self.lr, self.sweeps, self.balanced,
        )  # fmt: skip
        self.weight[pi, ki] = params[:, :-1]
        self.bias[pi, ki] = params[:, -1]

    # ----------------------------------------------------------------------------- slots
    def constrain(self, mask: Tensor) -> None:
        """Turn the distance constraint on for the slots in ``mask [P, K]`` (learned options)."""
        self.constrained |= check_slot_mask(mask, self.population, self.slots).to(self.seeds.device)

    @torch.no_grad()
    def reset_slots(self, mask: Tensor) -> None:
        """Forget the slots in ``mask [P, K]``: no data, zero weights and the initial bias."""
        mask = check_slot_mask(mask, self.population, self.slots).to(self.seeds.device)
        pi, ki = mask.nonzero().unbind(-1)  # index the few slots, not a mask over the stores
        self.weight[pi, ki] = 0.0
        self.bias[pi, ki] = self.initial_bias
        self.examples[pi, ki] = 0.0
        self.labels[pi, ki] = False
        for name in ("count", "seen", "sweeps_done"):
            getattr(self, name)[pi, ki] = 0
        for name in ("trained", "constrained", "dirty"):
            getattr(self, name)[pi, ki] = False
        self.generation[pi, ki] += 1

    def reset_slot(self, agents: int | Tensor, slot: int | Tensor) -> None:
        self.reset_slots(slot_mask(agents, slot, self.slots, self.population, self.seeds.device))

    # ----------------------------------------------------------------------------- convergence
    def snapshot(self) -> Tensor:
        """A copy of every slot's weights and bias, ``[P, K, F + 1]``; for a model of a
        subclass's own, its logits at fixed probe points (:func:`.initiation_fit.snapshot`)."""
        if not self.builtin_model():
            return initiation_fit.snapshot(self)
        return torch.cat([self.weight, self.bias[..., None]], dim=-1).detach().clone()

    def make_optimizer(self, params: list[nn.Parameter]) -> torch.optim.Optimizer:
        """The optimizer that fits a subclass's own model (each fit makes a new one): plain
        SGD at ``lr``, the built-in fit's step. Override it for Adam and the like."""
        return torch.optim.SGD(params, lr=self.lr)

    def weight_change(self, before: Tensor, after: Tensor | None = None) -> Tensor:
        """Mean absolute change per weight (bias included) between snapshots: ``[P, K]``.

        The paper's convergence test compares it with 0.15 per episode. For a subclass's own
        model the snapshots are logits at probe points, so it is the mean change of the logit.
        """
        after = self.snapshot() if after is None else after
        if before.shape != after.shape:
            raise ValueError(f"snapshots differ in shape: {tuple(before.shape)} vs "
                             f"{tuple(after.shape)}")  # fmt: skip
        return rowwise_sum(torch.abs(after - before)) / float(after.shape[-1])

    def select_agents(self, index, seeds: Tensor | None = None) -> InitiationClassifier:
        """A new classifier holding agents ``index`` (repeats allowed), optionally reseeded."""
        index = agent_index(index, self.population).to(self.seeds.device)
        new = type(self)(**{**self.config, "population": len(index)}, device=self.seeds.device)
        state = {name: value[index] for name, value in self.state_dict().items()
                 if not name.startswith("features.")}  # fmt: skip
        if seeds is not None:
            state["seeds"] = torch.as_tensor(seeds, dtype=torch.int64).reshape(-1)
        new.load_state_dict({**new.state_dict(), **state})
        return new

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.config.items() if k != "dtype") + (
            f", features={self.num_features}"
        )

    # ------------------------------------------------------------------ example stores, distance
    def _within(self, points: Tensor, examples: Tensor) -> Tensor:
        """``|point - example| <= distance`` (in ``distance_dims``) for every pair:
        ``points [..., N, 4]``, ``examples [..., M, 4]`` -> ``[..., N, M]``.

        ``cdist`` without the matrix-product shortcut computes each pair on its own (one
        kernel instead of a dozen elementwise operations, and the same bits whatever the batch
        around it, which ``tests/options/test_initiation.py`` checks).
        """
        if len(self.distance_dims) < self.obs_dim:
            dims = list(self.distance_dims)
            points, examples = points[..., dims], examples[..., dims]
        distance = torch.cdist(points, examples, compute_mode="donot_use_mm_for_euclid_dist")
        return distance <= self.distance

    def near_points(self, agent: int, slot: int, points: Tensor, member: Tensor) -> Tensor:
        """``member [N]`` narrowed to the points within ``distance`` of one of slot ``slot``'s
        stored positives (agent ``agent``), tested only where ``member`` holds and only against
        positives in neighbouring cells (:func:`~.nearby.within_any`): the dense matrix's
        answer, bit for bit, in a tenth of its time on a Figure-5 probe grid."""
        count = int(self.count[agent, slot])
        positives = self.examples[agent, slot, :count][self.labels[agent, slot, :count]]
        near = torch.zeros_like(member)
        rows = member.nonzero().flatten()
        if positives.shape[0] > 0 and rows.numel() > 0:
            dims = list(self.distance_dims)
            near[rows] = within_any(points[rows][:, dims], positives[:, dims], self.distance)
        near = member & near
        return self.nearest_points(agent, slot, points, near) if self.constrain_nearest else near

    def _nearest_positive(self, points: Tensor, examples: Tensor, labels: Tensor,
                          stored: Tensor) -> Tensor:  # fmt: skip
        """``constrain_nearest``: no stored negative strictly nearer to each point than its
        nearest stored positive. ``points [B, N, 4]``, ``examples [B, C, 4]``, ``labels`` and
        ``stored [B, C]`` -> ``[B, N]``."""
        if len(self.distance_dims) < self.obs_dim:
            dims = list(self.distance_dims)
            points, examples = points[..., dims], examples[..., dims]
        distance = torch.cdist(points, examples, compute_mode="donot_use_mm_for_euclid_dist")
        far = torch.full_like(distance, torch.inf)
        positive = torch.where((stored & labels)[:, None, :], distance, far).amin(-1)
        negative = torch.where((stored & ~labels)[:, None, :], distance, far).amin(-1)
        return ~(negative < positive)

    def nearest_points(self, agent: int, slot: int, points: Tensor, member: Tensor) -> Tensor:
        """``member [N]`` narrowed by ``constrain_nearest`` (only where ``member`` holds)."""
        count = int(self.count[agent, slot])
        labels = self.labels[agent, slot, :count]
        rows = member.nonzero().flatten()
        if bool(labels.all()) or rows.numel() == 0:  # no stored failure: nothing changes
            return member
        stored = torch.ones_like(labels)
        keep = self._nearest_positive(points[rows][None], self.examples[agent, slot, :count][None],
                                      labels[None], stored[None])[0]  # fmt: skip
        return member.index_put((rows,), keep)

    def near_positive(self, obs: Tensor, mask: Tensor | None = None) -> Tensor:
        """``[P, K]``: within ``distance`` of at least one stored positive example (with
        ``constrain_nearest``, and no stored negative nearer than the nearest positive).

        Only the slots in ``mask [P, K]`` (default all) are checked; others read False.
        """
        obs = self._check_obs(obs)
        mask = torch.ones_like(self.trained) if mask is None else mask
        mask = check_slot_mask(mask, self.population, self.slots)
        if bool(mask.all()):  # every slot: work on the stores in place, no gather
            examples, count, labels = self.examples, self.count, self.labels
            point = obs[:, None, :].expand(-1, self.slots, -1)
        else:
            pi, ki = mask.nonzero().unbind(-1)
            examples, count, labels = self.examples[pi, ki], self.count[pi, ki], self.labels[pi, ki]
            point = obs[pi]
        stored = torch.arange(self.capacity, device=obs.device) < count[..., None]
        d = self.obs_dim
        within = self._within(point.reshape(-1, 1, d), examples.reshape(-1, self.capacity, d))
        near = (within.reshape(stored.shape) & stored & labels).any(-1)
        if self.constrain_nearest:  # ... and no stored failure nearer than that positive
            shape = stored.shape
            near = near & self._nearest_positive(
                point.reshape(-1, 1, d), examples.reshape(-1, self.capacity, d),
                labels.reshape(-1, self.capacity), stored.reshape(-1, self.capacity),
            )[:, 0].reshape(shape[:-1])
        if bool(mask.all()):
            return near
        out = torch.zeros_like(self.trained)
        out[pi, ki] = near
        return out

    def add_examples(self, agents: int | Tensor, slots: int | Tensor, obs: Tensor,
                     labels: Tensor) -> Tensor:  # fmt: skip
        """Store labelled examples (in order) and mark their slots for refitting.

        Args:
            agents, slots: int (all examples) or ``LongTensor [N]`` (one per example).
            obs: ``[N, 4]`` observations; labels: ``[N]`` bool or 0/1 (positive = in the set).

        Returns:
            ``BoolTensor [P, K]``: the slots that received data.
        """
        if obs.ndim != 2 or obs.shape[-1] != self.obs_dim:
            raise ValueError(f"obs must be [N, {self.obs_dim}], got {tuple(obs.shape)}")
        n, device = obs.shape[0], self.examples.device
        if labels.shape != (n,):
            raise ValueError(f"labels must be [N={n}], got {tuple(labels.shape)}")
        p = torch.as_tensor(agents, dtype=torch.int64, device=device).expand(n)
        k = torch.as_tensor(slots, dtype=torch.int64, device=device).expand(n)
        if self._kernel is not None:  # one compiled pass, the same places and bits
            touched = self._kernel.add_examples(self, p, k, obs, labels)
            if touched is None:
                raise ValueError(f"agent/slot indices out of range for P={self.population}, "
                                 f"K={self.slots}")  # fmt: skip
            self.dirty |= touched
            return touched
        if bool(((p < 0) | (p >= self.population) | (k < 0) | (k >= self.slots)).any()):
            raise ValueError(f"agent/slot indices out of range for P={self.population}, "
                             f"K={self.slots}")  # fmt: skip
        touched = torch.zeros(self.population * self.slots, dtype=torch.bool, device=device)
        if n == 0:
            return touched.reshape(self.population, self.slots)
        labels = labels.to(device).to(torch.bool)
        failures = self.store_failures and self.replacement == "reservoir"
        if n > 1 and ((self.keep_negatives and not bool((labels == labels[0]).all()))
                      or (failures and not bool(labels.all()))):  # fmt: skip
            # Mixed labels: one at a time, so each positive sees the labels stored before it.
            for i in range(n):
                touched |= self.add_examples(p[i], k[i], obs[i:i + 1], labels[i:i + 1]).reshape(-1)
            return touched.reshape(self.population, self.slots)
        flat = p * self.slots + k
        if failures and not bool(labels[0]) and int(self.seen[p[0], k[0]]) >= self.capacity:
            return self._store_failure(p[0], k[0], obs[0])
        cell, keep = store_places(flat, self.seen.reshape(-1), self.seeds[p], k,
                                  self.generation[p, k], self.capacity, self.replacement)
        if self.keep_negatives and bool(labels[0]):
            # All positive: drop those landing on a place that held a negative before this
            # batch (a place filled earlier in the batch holds a positive).
            store, place = cell // self.capacity, cell % self.capacity
            held = place < self.count.view(-1)[store]
            negative = held & ~self.labels.view(-1)[cell]
            cell, keep = cell[~negative], keep[~negative]
        self.examples.view(-1, self.obs_dim)[cell] = obs[keep].to(self.examples.dtype)
        self.labels.view(-1)[cell] = labels[keep]
        self.seen.view(-1).index_add_(0, flat, torch.ones_like(flat))
        self.count.copy_(torch.clamp(self.seen, max=self.capacity))
        touched[flat] = True
        touched = touched.reshape(self.population, self.slots)
        self.dirty |= touched
        return touched

    def _store_failure(self, p: Tensor, k: Tensor, point: Tensor) -> Tensor:
        """A negative example of agent ``p``'s full slot ``k`` under ``store_failures``: it
        takes :func:`~.examples.failure_place`, whatever the reservoir would have drawn."""
        place = failure_place(self.seeds[p], k, self.generation[p, k], self.seen[p, k],
                              self.capacity, self.labels[p, k])  # fmt: skip
        self.examples[p, k, place] = point.to(self.examples.dtype)
        self.labels[p, k, place] = False
        self.seen[p, k] += 1
        self.count.copy_(torch.clamp(self.seen, max=self.capacity))
        touched = torch.zeros_like(self.dirty)
        touched[p, k] = True
        self.dirty |= touched
        return touched

    def stored_classes(self) -> tuple[Tensor, Tensor]:
        """``(positive, negative)`` ``[P, K]``: the slot stores an example of that class."""
        stored = torch.arange(self.capacity, device=self.labels.device) < self.count[..., None]
        return (self.labels & stored).any(-1), (~self.labels & stored).any(-1)

    def has_both_classes(self) -> Tensor:
        """``[P, K]``: the slot stores at least one positive and one negative example."""
        positive, negative = self.stored_classes()
        return positive & negative
