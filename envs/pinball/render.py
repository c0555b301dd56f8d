"""Drawing Pinball boards: RGB frames in pure numpy, and trajectory plots in matplotlib.

Both follow the original renderers' orientation: x runs along screen columns and y along
screen rows with y = 0 at the top, so ``start 0.2 0.9`` is bottom-left.

Example:
    >>> from skillchain_torch.envs.pinball.maps import load_map
    >>> frame = render_frame(load_map("pinball_simple_single"), state=(0.2, 0.9, 0.0, 0.0))
    >>> frame.shape, frame.dtype
    ((400, 400, 3), dtype('uint8'))
"""

from __future__ import annotations

import weakref

import numpy as np
import torch

__all__ = [
    "BACKGROUND_COLOR",
    "BALL_COLOR",
    "POLYGON_COLOR",
    "TARGET_COLOR",
    "plot_trajectories",
    "render_frame",
]

BACKGROUND_COLOR = (245, 245, 240)
POLYGON_COLOR = (70, 70, 70)
TARGET_COLOR = (220, 30, 30)
BALL_COLOR = (30, 80, 220)

# map -> {size: read-only background}. Weak keys: a cached board goes away with its map, and
# a new map reusing a freed map's id() can never pick up the old picture.
_BACKGROUNDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _as_numpy(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu()
        # numpy has no bfloat16; everything we draw is small, so float64 costs nothing
        x = x.to(torch.float64) if x.is_floating_point() else x
        return x.numpy()
    return np.asarray(x)


def _inside_polygon(vertices: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Even-odd test of points (px [1, W] against py [H, 1]) against one polygon: [H, W] bool."""
    inside = np.zeros(np.broadcast_shapes(px.shape, py.shape), dtype=bool)
    x1, y1 = vertices[:, 0], vertices[:, 1]
    x2, y2 = np.roll(x1, -1), np.roll(y1, -1)
    for a, b, c, d in zip(x1, y1, x2, y2, strict=True):
        if b == d:  # horizontal edges never cross a horizontal ray
            continue
        spans = (b > py) != (d > py)  # [H, 1]: rows whose ray meets the edge's height
        x_cross = a + (py - b) * (c - a) / (d - b)  # [H, 1]
        inside ^= spans & (px < x_cross)
    return inside


def _background(pinball_map, size: int) -> np.ndarray:
    per_map = _BACKGROUNDS.setdefault(pinball_map, {})
    if size in per_map:
        return per_map[size]
    centres = (np.arange(size) + 0.5) / size  # pixel centres in board units
    px, py = centres[None, :], centres[:, None]
    frame = np.empty((size, size, 3), dtype=np.uint8)
    frame[:] = BACKGROUND_COLOR
    solid = np.zeros((size, size), dtype=bool)
    for poly in pinball_map.polygons:
        solid |= _inside_polygon(_as_numpy(poly).astype(np.float64), px, py)
    frame[solid] = POLYGON_COLOR
    tx, ty = pinball_map.target
    # Drawn over the obstacles so the goal stays visible even where it overlaps one.
    frame[(px - tx) ** 2 + (py - ty) ** 2 <= pinball_map.target_radius**2] = TARGET_COLOR
    frame.flags.writeable = False
    per_map[size] = frame
    return frame


def render_frame(pinball_map, state=None, size: int = 400) -> np.ndarray:
    """An RGB picture of the board, with the ball at ``state`` (x, y, ...) if given.

    The static board (background, obstacles, target) is rasterised once per map and size and
    cached; each call copies it and paints the ball. ``state`` is a raw state, i.e. its first
    two entries are the ball centre in board units; torch tensors, numpy arrays and sequences
    work. A ball partly off the board is clipped.

    Returns:
        ``uint8`` array of shape ``[size, size, 3]`` (row 0 is y = 0).

    Example:
        >>> from skillchain_torch.envs.pinball.maps import load_map
        >>> frame = render_frame(load_map("pinball_simple_single"), (0.2, 0.9), size=100)
        >>> frame[90, 20].tolist()  # row = y * size, column = x * size
        [30, 80, 220]
    """
    size = int(size)
    if size < 1:
        raise ValueError(f"size must be a positive number of pixels, got {size}")
    frame = _background(pinball_map, size).copy()
    if state is None:
        return frame
    xy = _as_numpy(state).reshape(-1)
    if xy.shape[0] < 2:
        raise ValueError(f"state needs at least x and y, got shape {np.shape(state)}")
    x, y = float(xy[0]), float(xy[1])
    if not (np.isfinite(x) and np.isfinite(y)):
        raise ValueError(f"cannot draw a ball at a non-finite position ({x}, {y})")
    r = pinball_map.ball_radius
    # Only the pixels in the ball's bounding box can be inside it.
    lo_c, hi_c = max(int((x - r) * size), 0), min(int((x + r) * size) + 2, size)
    lo_r, hi_r = max(int((y - r) * size), 0), min(int((y + r) * size) + 2, size)
    if lo_c >= hi_c or lo_r >= hi_r:
        return frame
    cols = (np.arange(lo_c, hi_c) + 0.5) / size
    rows = (np.arange(lo_r, hi_r) + 0.5) / size
    disc = (cols[None, :] - x) ** 2 + (rows[:, None] - y) ** 2 <= r * r
    frame[lo_r:hi_r, lo_c:hi_c][disc] = BALL_COLOR
    return frame


def _is_single_color(c) -> bool:
    from matplotlib.colors import is_color_like

    # A 2-D array of per-step colours is never one colour; checked first because
    # is_color_like() would try to parse it as a single RGBA tuple.
    return not (isinstance(c, np.ndarray) and c.ndim > 1) and is_color_like(c)


def _trajectory_list(trajectories) -> list[np.ndarray]:
    if isinstance(trajectories, (torch.Tensor, np.ndarray)):
        arr = _as_numpy(trajectories)
        if arr.ndim == 2:  # one trajectory passed on its own
            return [arr]
        return list(arr)
    return [_as_numpy(t) for t in trajectories]


def plot_trajectories(
    pinball_map,
    trajectories,
    colors=None,
    ax=None,
    labels=None,
    linewidth: float = 1.5,
    show_starts: bool = True,
):
    """Plot the board and ball paths; returns the matplotlib ``Axes``.

    Args:
        pinball_map: a ``PinballMap``.
        trajectories: a list of array-likes ``[T, >=2]`` (raw states or x, y; torch or
            numpy), or one ``[T, >=2]`` / ``[N, T, >=2]`` array.
        colors: one entry per trajectory, each either one matplotlib colour, or a sequence of
            T (or T - 1) colours, one per step: the segment from step t to t + 1 takes colour
            t. Per-step colours are drawn as a ``LineCollection`` (e.g. colouring a path by
            the option in control). Something that is itself a colour, like ``(1, 0, 0)``,
            counts as one colour. Default: the colour cycle C0, C1, ...
        ax: axes to draw into; a new figure is made with ``plt.subplots`` only if None.
        labels: optional legend labels, one per trajectory (a legend is added if any).
        linewidth: width of the trajectory lines.
        show_starts: mark the start positions (a scatter, so not counted among lines).

    Obstacles are ``Polygon`` patches and the target a ``Circle``; each single-colour
    trajectory is one ``Line2D``. The y axis runs downwards (y = 0 at the top).

    Example:
        >>> import matplotlib; matplotlib.use("Agg")
        >>> from skillchain_torch.envs.pinball.maps import load_map
        >>> ax = plot_trajectories(load_map("pinball_simple_single"),
        ...                        [[(0.2, 0.9), (0.25, 0.85), (0.3, 0.7)]],
        ...                        colors=[["C0", "C1", "C1"]])
        >>> len(ax.collections)  # the start marker and the per-step coloured path
        2
    """
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Polygon

    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(5, 5))
    trajs = _trajectory_list(trajectories)
    if colors is not None and len(colors) != len(trajs):
        raise ValueError(f"got {len(colors)} colours for {len(trajs)} trajectories")
    if labels is not None and len(labels) != len(trajs):
        raise ValueError(f"got {len(labels)} labels for {len(trajs)} trajectories")

    for poly in pinball_map.polygons:
        ax.add_patch(
            Polygon(
                _as_numpy(poly),
                closed=True,
                facecolor=np.array(POLYGON_COLOR) / 255,
                edgecolor="none",
                zorder=1,
            )
        )
    ax.add_patch(
        Circle(
            pinball_map.target,
            pinball_map.target_radius,
            facecolor=np.array(TARGET_COLOR) / 255,
            edgecolor="none",
            zorder=2,
        )
    )
    if show_starts:
        s = _as_numpy(pinball_map.starts)
        ax.scatter(s[:, 0], s[:, 1], marker="s", s=30, color="black", zorder=4, label=None)

    for i, traj in enumerate(trajs):
        if traj.ndim != 2 or traj.shape[1] < 2:
            raise ValueError(f"trajectory {i} must have shape [T, >=2], got {traj.shape}")
        xy = traj[:, :2].astype(np.float64)
        color = f"C{i % 10}" if colors is None else colors[i]
        label = None if labels is None else labels[i]
        if _is_single_color(color):
            ax.plot(xy[:, 0], xy[:, 1], color=color, linewidth=linewidth, label=label, zorder=3)
            continue
        from matplotlib.colors import to_rgba_array

        rgba = to_rgba_array(color)
        n_seg = max(len(xy) - 1, 0)
        if len(rgba) not in (len(xy), n_seg):
            raise ValueError(f"trajectory {i} has {len(xy)} steps but {len(rgba)} colours")
        segments = np.stack([xy[:-1], xy[1:]], axis=1)  # [T-1, 2, 2]
        ax.add_collection(
            LineCollection(
                segments, colors=rgba[:n_seg], linewidths=linewidth, label=label, zorder=3
            )
        )

    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(1.0, 0.0)  # set, not invert_yaxis(): calling twice on one ax must not flip back
    ax.set_aspect("equal")
    if labels is not None and any(label is not None for label in labels):
        ax.legend(loc="best", fontsize="small")
    return ax
