"""Pinball instances as tensors: :class:`PinballMap`, and the shipped maps (:data:`MAP_NAMES`,
:func:`load_map`).

A map is read from a ``.cfg`` file (the Konidaris & Barto format, parsed and checked by
:mod:`.map_parser`: every problem is a ``ValueError`` naming the file, the line and the
problem) into float64 tensors: the ball radius, the goal disc, the start positions and the
polygon obstacles, with their edges flattened for the physics.

Example:
    >>> m = load_map("pinball_simple_single"); m.n_polygons
    10
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import torch

from .map_parser import parse_map

__all__ = ["MAP_NAMES", "PinballMap", "load_map"]

# The package this module lives in; resolves to "skillchain_torch.envs.pinball" once installed.
_PACKAGE = __name__.rpartition(".")[0] or "skillchain_torch.envs.pinball"


def _maps_dir():
    return resources.files(_PACKAGE) / "maps"


def _discover() -> tuple[str, ...]:
    try:
        entries = list(_maps_dir().iterdir())
    except (ModuleNotFoundError, FileNotFoundError, NotADirectoryError):
        return ()
    return tuple(sorted(e.name[:-4] for e in entries if e.name.endswith(".cfg")))


MAP_NAMES: tuple[str, ...] = _discover()


@dataclass(frozen=True, eq=False, repr=False)
class PinballMap:
    """One Pinball instance: ball radius, goal disc, start positions and polygon obstacles.

    All geometry is float64 by default, in the file's coordinates (unit square, y down on
    screen). Edges are flattened over polygons in file order, each polygon's edges in vertex
    order including the closing edge, so ``edge_polygon`` maps each edge back to its polygon.
    Equality and hashing are by identity (tensors have no useful ``==``).

    Example:
        >>> m = PinballMap.from_string("ball 0.02\\ntarget 0.9 0.2 0.04\\nstart 0.2 0.9\\n"
        ...                            "polygon 0.4 0.4 0.6 0.4 0.5 0.6")
        >>> m.n_polygons, m.n_edges, tuple(m.starts.shape)
        (1, 3, (1, 2))
    """

    name: str
    ball_radius: float
    target: tuple[float, float]
    target_radius: float
    starts: torch.Tensor
    polygons: tuple[torch.Tensor, ...]
    edge_start: torch.Tensor
    edge_end: torch.Tensor
    edge_polygon: torch.Tensor
    bbox: torch.Tensor
    source: str

    @classmethod
    def from_string(cls, text: str, name: str = "<string>", source: str = "<string>") -> PinballMap:
        """Parse map text; ``source`` is the name used in error messages.

        Example:
            >>> PinballMap.from_string("ball 0.02\\ntarget 0.9 0.2 0.04\\nstart 0.2 0.9 0.1 0.1"
            ...                        ).starts.tolist()
            [[0.2, 0.9], [0.1, 0.1]]
        """
        if not isinstance(text, str):
            raise TypeError(f"map text must be str, not {type(text).__name__}")
        parsed = parse_map(text, source)
        f64 = torch.float64
        polygons = tuple(torch.tensor(p, dtype=f64) for p in parsed["polygons"])
        if polygons:
            edge_start = torch.cat(polygons)
            edge_end = torch.cat([torch.roll(p, -1, dims=0) for p in polygons])
            counts = torch.tensor([len(p) for p in polygons])
            edge_polygon = torch.repeat_interleave(torch.arange(len(polygons)), counts)
            # Java starts max at 0 and min at 1; the same as the true box inside [0, 1].
            bbox = torch.stack([torch.cat([p.amin(0), p.amax(0)]) for p in polygons])
        else:
            edge_start = edge_end = torch.zeros(0, 2, dtype=f64)
            edge_polygon = torch.zeros(0, dtype=torch.int64)
            bbox = torch.zeros(0, 4, dtype=f64)
        tx, ty, tr = parsed["target"]
        return cls(
            name=name,
            ball_radius=parsed["ball"],
            target=(tx, ty),
            target_radius=tr,
            starts=torch.tensor(parsed["starts"], dtype=f64),
            polygons=polygons,
            edge_start=edge_start,
            edge_end=edge_end,
            edge_polygon=edge_polygon,
            bbox=bbox,
            source=source,
        )

    @classmethod
    def from_file(cls, path) -> PinballMap:
        """Read a ``.cfg`` file (UTF-8; a BOM is allowed). A missing file raises OSError.

        Example:
            >>> m = PinballMap.from_file(_maps_dir() / "pinball_box.cfg"); m.name
            'pinball_box'
        """
        source = str(path)
        # Path and importlib.resources Traversable objects both have read_bytes().
        data = (path if hasattr(path, "read_bytes") else Path(path)).read_bytes()
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise ValueError(
                f"{source}: not UTF-8 text ({err.reason} at byte {err.start})"
            ) from None
        name = str(getattr(path, "name", Path(source).name)).removesuffix(".cfg")
        return cls.from_string(text, name=name, source=source)

    def to(self, device=None, dtype=None) -> PinballMap:
        """A copy with tensors on ``device`` and floats in ``dtype`` (None keeps the current one).

        ``edge_polygon`` stays int64. Example:
            >>> load_map("pinball_box").to(dtype=torch.float32).dtype
            torch.float32
        """
        if dtype is not None and not dtype.is_floating_point:
            raise ValueError(f"dtype must be a floating point type, not {dtype}")

        def move(t):
            return t.to(device=device, dtype=dtype)

        return dataclasses.replace(
            self,
            starts=move(self.starts),
            polygons=tuple(move(p) for p in self.polygons),
            edge_start=move(self.edge_start),
            edge_end=move(self.edge_end),
            edge_polygon=self.edge_polygon.to(device=device),
            bbox=move(self.bbox),
        )

    @property
    def n_polygons(self) -> int:
        return len(self.polygons)

    @property
    def n_edges(self) -> int:
        return int(self.edge_start.shape[0])

    @property
    def device(self) -> torch.device:
        return self.starts.device

    @property
    def dtype(self) -> torch.dtype:
        return self.starts.dtype

    def __repr__(self) -> str:
        return (
            f"PinballMap({self.name!r}, ball_radius={self.ball_radius}, "
            f"target=({self.target[0]}, {self.target[1]}, r={self.target_radius}), "
            f"starts={self.starts.shape[0]}, polygons={self.n_polygons})"
        )


def load_map(name: str, device=None, dtype=torch.float64) -> PinballMap:
    """Load a shipped map by name (with or without ``.cfg``); see ``MAP_NAMES``.

    Example:
        >>> m = load_map("pinball_simple_single"); m.n_polygons
        10
        >>> load_map("pinball_hard_two_starts.cfg").starts.shape[0]
        2
    """
    stem = str(name).removesuffix(".cfg")
    if stem not in MAP_NAMES:
        raise ValueError(f"unknown pinball map {name!r}; known maps: {', '.join(MAP_NAMES)}")
    return PinballMap.from_file(_maps_dir() / f"{stem}.cfg").to(device=device, dtype=dtype)
