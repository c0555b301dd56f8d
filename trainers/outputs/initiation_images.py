"""Pictures and probes of initiation sets: the paper's Figure 5 density of a set, its image for
TensorBoard, and :class:`SlotMemo`, which remembers a slot's membership on a probe grid until
the slot's classifier changes.

Plain functions for notebooks (:func:`initiation_density`, :func:`plot_initiation_set`), used
by :class:`~.option_monitor.OptionMonitor` and :class:`~.discovery_log.DiscoveryLog`.

Example:
    >>> import torch
    >>> from skillchain_torch.options import InitiationClassifier
    >>> clf = InitiationClassifier(1, 1)
    >>> with torch.no_grad():
    ...     clf.weight[0, 0, 1] = -1.0; clf.bias[0, 0] = 0.5   # x < 0.5
    ...     clf.trained[0, 0] = True
    >>> d = initiation_density(clf, 0, 0, resolution=4)
    >>> d.tolist()[0]                                          # one row: y fixed, x varies
    [1.0, 1.0, 0.0, 0.0]
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from skillchain_torch.options import InitiationClassifier, OptionBank

__all__ = [
    "VELOCITIES",
    "probe_observations",
    "contains_many",
    "initiation_density",
    "initiation_image",
    "plot_initiation_set",
    "SlotMemo",
    "board_masks",
]

# Figure 5: xdot and ydot sampled over {-1, -1/2, 0, 1/2, 1} (raw velocities).
VELOCITIES = (-1.0, -0.5, 0.0, 0.5, 1.0)


def probe_observations(resolution: int = 50, velocities=VELOCITIES,
                       dtype: torch.dtype = torch.float64, device=None, dim: int = 4) -> Tensor:
    """Observations ``[R * R * V * V, 4]`` of a Figure-5 probe grid.

    Positions are the centres of an ``R x R`` grid on the unit board, velocities every pair of
    ``velocities`` (raw, mapped to the descriptor ``(v + 1) / 2``). The order is
    ``(y, x, xdot, ydot)`` from slowest to fastest, so a result reshaped to
    ``[R, R, V * V]`` is indexed ``[row = y, column = x, velocity pair]``.

    Off Pinball (``dim != 4``) the grid spans observation dims 0 and 1 of the unit box and the
    other dims sit at the centre, 0.5: ``[R * R, dim]``, a slice of the set.
    """
    if resolution < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    centres = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution
    if dim != 4:
        y, x = torch.meshgrid(centres, centres, indexing="ij")
        rest = torch.full((resolution * resolution, max(dim - 2, 0)), 0.5, dtype=dtype,
                          device=device)  # fmt: skip
        return torch.cat([x.reshape(-1, 1), y.reshape(-1, 1), rest], dim=1)[:, :dim]
    vel = (torch.as_tensor(velocities, dtype=dtype, device=device) + 1.0) / 2.0
    y, x, vx, vy = torch.meshgrid(centres, centres, vel, vel, indexing="ij")
    return torch.stack([x, y, vx, vy], dim=-1).reshape(-1, 4)


def _classifier(source) -> InitiationClassifier:
    if isinstance(source, OptionBank):
        return source.classifier
    if isinstance(source, InitiationClassifier):
        return source
    bank = getattr(source, "bank", None)  # an agent
    if isinstance(bank, OptionBank):
        return bank.classifier
    raise TypeError(f"expected an InitiationClassifier, an OptionBank or an agent with a bank, "
                    f"got {type(source).__name__}")


@torch.no_grad()
def contains_many(classifier: InitiationClassifier, agent: int, slot: int,
                  obs: Tensor) -> Tensor:
    """``BoolTensor [N]``: membership of ``obs [N, 4]`` in agent ``agent``'s slot ``slot``
    (:meth:`InitiationClassifier.contains_points`)."""
    return classifier.contains_points(agent, slot, obs)


def initiation_density(classifier_or_bank, agent: int = 0, slot: int = 0,
                       resolution: int = 50, velocities=VELOCITIES) -> np.ndarray:
    """The paper's Figure 5 density of an initiation set: ``float64 [resolution, resolution]``.

    Entry ``[j, i]`` is the fraction of the ``len(velocities) ** 2`` velocity pairs (default
    the 25 pairs of ``{-1, -1/2, 0, 1/2, 1}``) for which the observation at the centre of cell
    (column ``i`` = x, row ``j`` = y; y runs downwards as on the board) lies in the set, so
    lightness is proportional to the number of velocity combinations inside it.

    Args:
        classifier_or_bank: an :class:`InitiationClassifier`, an :class:`OptionBank` or an
            agent with a ``bank``.
        agent, slot: which agent's which option.
        resolution: cells per side.
    """
    clf = _classifier(classifier_or_bank)
    if not (0 <= agent < clf.population and 0 <= slot < clf.slots):
        raise ValueError(f"agent {agent}, slot {slot} out of range for P={clf.population}, "
                         f"K={clf.slots}")
    obs = probe_observations(resolution, velocities, dtype=clf.weight.dtype,
                             device=clf.weight.device, dim=clf.obs_dim)
    member = contains_many(clf, agent, slot, obs).reshape(resolution, resolution, -1)
    return member.to(torch.float64).mean(-1).cpu().numpy()


def board_masks(pinball_map, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """``(obstacle, target)`` bool ``[R, R]`` masks of the cell centres (row = y)."""
    from skillchain_torch.agents.region_option import inside_obstacle

    centres = (np.arange(resolution) + 0.5) / resolution
    y, x = np.meshgrid(centres, centres, indexing="ij")
    points = torch.as_tensor(np.stack([x.ravel(), y.ravel()], -1), dtype=torch.float64)
    obstacle = inside_obstacle(points, pinball_map).numpy().reshape(resolution, resolution)
    tx, ty = pinball_map.target
    target = (x - tx) ** 2 + (y - ty) ** 2 <= pinball_map.target_radius ** 2
    return obstacle, target


def initiation_image(density: np.ndarray, pinball_map=None, scale: int = 4,
                     masks=None) -> np.ndarray:
    """``uint8 [R * scale, R * scale, 3]`` (HWC) picture of a density: grey levels = density,
    obstacle cells tinted blue and target cells red when ``pinball_map`` is given
    (``masks``: its :func:`board_masks` at this resolution, if already computed)."""
    d = np.clip(np.asarray(density, dtype=np.float64), 0.0, 1.0)
    rgb = np.repeat(d[..., None], 3, axis=-1)
    if pinball_map is not None:
        obstacle, target = masks if masks is not None else board_masks(pinball_map, d.shape[0])
        rgb[obstacle] = 0.5 * rgb[obstacle] + 0.5 * np.array([0.2, 0.35, 0.8])
        rgb[target] = np.array([0.9, 0.1, 0.1])
    image = (rgb * 255.0 + 0.5).astype(np.uint8)
    return np.kron(image, np.ones((scale, scale, 1), dtype=np.uint8)) if scale > 1 else image


def plot_initiation_set(classifier_or_bank, agent: int = 0, slot: int = 0, pinball_map=None,
                        ax=None, resolution: int = 50, cmap: str = "gray", colorbar: bool = False,
                        title: str | None = None):
    """Draw :func:`initiation_density` as an image (with the board's obstacles and target on top
    when ``pinball_map`` is given); returns the matplotlib ``Axes``.

    Example:
        >>> import matplotlib; matplotlib.use("Agg")
        >>> from skillchain_torch.options import InitiationClassifier
        >>> ax = plot_initiation_set(InitiationClassifier(1, 1), resolution=5)
        >>> ax.images[0].get_array().shape
        (5, 5)
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(5, 5))
    density = initiation_density(classifier_or_bank, agent, slot, resolution)
    image = ax.imshow(density, cmap=cmap, vmin=0.0, vmax=1.0, extent=(0.0, 1.0, 1.0, 0.0),
                      origin="upper", interpolation="nearest", zorder=0)
    if pinball_map is not None:
        from skillchain_torch.envs.pinball import plot_trajectories

        plot_trajectories(pinball_map, [], ax=ax, show_starts=False)
        for patch in ax.patches:
            patch.set_alpha(0.6)
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(1.0, 0.0)
    ax.set_aspect("equal")
    ax.set_title(title if title is not None else f"initiation set: agent {agent}, slot {slot}")
    if colorbar:
        ax.figure.colorbar(image, ax=ax, fraction=0.046, label="fraction of velocities in set")
    return ax


def _slot_state(clf: InitiationClassifier, p: int, k: int) -> tuple:
    """Copies of everything :meth:`InitiationClassifier.contains_points` reads of slot (p, k)."""
    count = int(clf.count[p, k])
    return (id(clf), float(clf.distance), tuple(clf.distance_dims), bool(clf.centered),
            bool(clf.trained[p, k]), bool(clf.constrained[p, k]), count,
            clf.weight[p, k].clone(), clf.bias[p, k].clone(),
            clf.examples[p, k, :count].clone(), clf.labels[p, k, :count].clone())


def _same(a: tuple, b: tuple) -> bool:
    return all(torch.equal(x, y) if isinstance(x, Tensor) else x == y for x, y in zip(a, b))


class SlotMemo:
    """Membership of a fixed probe grid in each (agent, slot)'s initiation set, recomputed
    only when that slot's classifier changed since the last call.

    The monitor asks for every live slot of every agent at every population episode, while a
    slot changes only when it is refitted or receives examples, so most answers repeat
    (measured on the 10 x 100 run: see ``benchmarks/README.md``). For the built-in
    :class:`InitiationClassifier` the memo keeps a copy of everything ``contains_points``
    reads of the slot (weights, bias, flags, stored examples and labels) and answers from
    memory while they are equal, so answers are those of a fresh call, bit for bit. Any
    other classifier type is asked every time: its membership may read state the memo does
    not know.

    Args:
        probe: observations ``[N, 4]`` (e.g. :func:`probe_observations`).

    Example:
        >>> clf = InitiationClassifier(1, 1)
        >>> memo = SlotMemo(probe_observations(4))
        >>> bool(memo.contains(clf, 0, 0).all()), bool(memo.contains(clf, 0, 0).all())
        (True, True)
        >>> memo.misses, memo.hits
        (1, 1)
        >>> with torch.no_grad():
        ...     clf.weight[0, 0, 1] = -1.0; clf.bias[0, 0] = 0.5; clf.trained[0, 0] = True
        >>> float(memo.contains(clf, 0, 0).double().mean()), memo.misses   # x < 0.5
        (0.5, 2)
    """

    def __init__(self, probe: Tensor):
        self.probe = probe
        self.hits = 0
        self.misses = 0
        self._seen: dict[tuple[int, int], tuple[tuple, Tensor]] = {}

    @torch.no_grad()
    def contains(self, classifier: InitiationClassifier, agent: int, slot: int) -> Tensor:
        """``BoolTensor [N]``: ``contains_many(classifier, agent, slot, probe)``."""
        p, k = int(agent), int(slot)
        state = _slot_state(classifier, p, k) if type(classifier) is InitiationClassifier else None
        seen = self._seen.get((p, k))
        if state is not None and seen is not None and _same(seen[0], state):
            self.hits += 1
            return seen[1]
        self.misses += 1
        member = contains_many(classifier, p, k, self.probe)
        if state is not None:
            self._seen[(p, k)] = (state, member)
        return member
