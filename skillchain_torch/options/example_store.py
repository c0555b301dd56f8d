"""The initiation sets' example stores: labelled states per slot, and the distance rule.

Skill chaining learns each initiation set from examples (paper section 5.1): the states of a
successful execution are positive, the start of a failed one negative. :class:`ExampleStores`
holds them, ``[P, K, C, D]`` with labels, counts and reservoir draws (:func:`store_places`), and
answers the post-learning constraint "within ``distance`` of a positive example". It is the
half of :class:`~skillchain_torch.options.InitiationClassifier` that does not depend on the
classifier's model, so a user's model (a subclass overriding ``logit``) keeps it unchanged.

Example:
    >>> import torch
    >>> from skillchain_torch.options import InitiationClassifier
    >>> clf = InitiationClassifier(population=1, slots=1, capacity=8)
    >>> x = torch.tensor([[0.2, 0.2, 0.5, 0.5], [0.9, 0.9, 0.5, 0.5]], dtype=torch.float64)
    >>> clf.add_examples(0, 0, x, torch.tensor([True, False])).tolist()
    [[True]]
    >>> [c.tolist() for c in clf.stored_classes()]
    [[[True]], [[True]]]
    >>> clf.near_positive(torch.tensor([[0.25, 0.2, 0.5, 0.5]], dtype=torch.float64)).tolist()
    [[True]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import initiation as backend
from skillchain_torch.backends.native import for_c
from skillchain_torch.options.examples import failure_place, store_places
from skillchain_torch.options.nearby import within_any
from skillchain_torch.options.status import check_slot_mask

__all__ = ["ExampleStores"]


class ExampleStores:
    """Mixin of :class:`~skillchain_torch.options.InitiationClassifier`: its stores.

    Reads the classifier's buffers ``examples [P, K, C, D]``, ``labels``, ``count``, ``seen``,
    ``generation``, ``seeds``, ``dirty`` and settings ``capacity``, ``replacement``,
    ``keep_negatives``, ``store_failures``, ``constrain_nearest``, ``distance``,
    ``distance_dims``, ``native``.
    """

    @property
    def stores(self) -> backend.Stores:
        """The stores' buffers and settings as the compiled kernels take them (they write
        the buffers in place)."""
        return backend.Stores(self.examples, self.labels, self.count, self.seen,
                              self.generation, self.seeds, self.replacement == "ring",
                              self.keep_negatives, self.store_failures)  # fmt: skip

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
        if self.native:  # one compiled pass, the same places and bits
            touched = torch.zeros(self.population, self.slots, dtype=torch.bool)
            if not backend.store(self.stores, p.contiguous(), k.contiguous(),
                                 for_c(obs, torch.float64), for_c(labels, torch.bool),
                                 touched):  # fmt: skip
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

