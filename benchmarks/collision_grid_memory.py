"""Build time and peak memory of the collision grid against the number of edges, in one run.

The grid (``envs/pinball/grid.py``) lists, per cell of a 128 x 128 grid, the edges a ball in
that cell could touch during a step. It used to be built as a dense ``cells x edges`` table:
a valid map of 20,000 small triangles (60,016 edges) then asked for 15.7 GB in one allocation
(the ``[cells, edges, 2]`` float64 differences alone) and was killed. It now keeps one list per
cell (CSR), so memory follows the (cell, edge) pairs that are near each other, about linear in
the number of edges. This script measures that on synthetic maps, beside the original maps
measured in the same process.

    python benchmarks/collision_grid_memory.py                   # up to 60,016 edges
    python benchmarks/collision_grid_memory.py --edges 100 1000  # chosen sizes
    python benchmarks/collision_grid_memory.py --threads 2

Maps: the shipped ``pinball_hard_single`` and ``pinball_simple_single`` (the references of the
ratio columns), ``triangles``: the four walls plus ``(E - 16) / 3`` small triangles (side
0.004) scattered over the board (60,016 edges: the 20,000 triangles of the report), and
``polygon``: the walls plus one round polygon of 20,000 vertices (radius 0.25).

Columns: ``entries``, the stored (cell, edge) pairs; ``build``, the wall time of
``CollisionGrid.build`` (best of ``--repeat``); ``peak``, the growth of the process's peak
resident memory during one build (Linux: the peak is reset through ``/proc/self/clear_refs``
before each build); ``estimate``, the upper bound that ``check_grid_size`` compares with the
limit before allocating; ``old dense``, what the dense layout's first allocation alone needed
(16 bytes x cells x edges). Ratios are against ``pinball_hard_single``.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import math
import random
import time
from pathlib import Path

import torch

from skillchain_torch.envs.pinball import PinballMap, load_map
from skillchain_torch.envs.pinball.grid import CollisionGrid, grid_memory_estimate

# Ball (0.02), target, start and the four walls of the original domain.
EMPTY = Path(load_map("pinball_empty").source).read_text() + "\n"


def triangles_map(n_edges: int, seed: int = 0, side: float = 0.004) -> PinballMap:
    """Walls plus ``(n_edges - 16) // 3`` small triangles away from the start and the target."""
    rnd = random.Random(seed)
    lines = []
    while len(lines) < (n_edges - 16) // 3:
        x, y = rnd.uniform(0.3, 0.95), rnd.uniform(0.3, 0.95)
        if math.dist((x, y), (0.9, 0.2)) > 0.1:
            lines.append(f"polygon {x!r} {y!r} {x + side!r} {y!r} {x!r} {y + side!r}")
    text = EMPTY + "\n".join(lines) + "\n"
    return PinballMap.from_string(text, name=f"triangles_{n_edges}", source="<triangles>")


def polygon_map(n_edges: int, centre=(0.6, 0.5), radius: float = 0.25) -> PinballMap:
    """Walls plus one round polygon of ``n_edges - 16`` vertices."""
    n = n_edges - 16
    points = " ".join(
        f"{centre[0] + radius * math.cos(2 * math.pi * k / n)!r} "
        f"{centre[1] + radius * math.sin(2 * math.pi * k / n)!r}"
        for k in range(n)
    )
    text = EMPTY + f"polygon {points}\n"
    return PinballMap.from_string(text, name=f"polygon_{n_edges}", source="<polygon>")


def _status_bytes(key: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _libc():
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


_LIBC = _libc()


def _release_freed_memory() -> None:
    """Hand memory freed by earlier builds back to the system (glibc), so that each build's
    peak counts its own pages rather than reusing ones left resident by the previous build."""
    gc.collect()
    if _LIBC is not None:
        _LIBC.malloc_trim(0)


def _reset_peak() -> bool:
    """Reset the process's peak RSS (VmHWM) to its current RSS; False where unsupported."""
    _release_freed_memory()
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def measure(pinball_map: PinballMap, repeat: int) -> dict:
    """One build under a fresh peak-RSS mark, then the best time of ``repeat`` builds."""
    peak = None
    if _reset_peak():
        base = _status_bytes("VmRSS:")
        start = time.perf_counter()
        grid = CollisionGrid.build(pinball_map)
        best = time.perf_counter() - start
        peak = _status_bytes("VmHWM:") - base
    else:
        start = time.perf_counter()
        grid = CollisionGrid.build(pinball_map)
        best = time.perf_counter() - start
    entries = grid.n_entries
    del grid
    for _ in range(repeat - 1):
        start = time.perf_counter()
        CollisionGrid.build(pinball_map)
        best = min(best, time.perf_counter() - start)
    estimate, _ = grid_memory_estimate(pinball_map)
    cells = 128 * 128
    return {
        "edges": pinball_map.n_edges,
        "entries": entries,
        "build": best,
        "peak": peak,
        "estimate": estimate,
        "dense": 16 * cells * pinball_map.n_edges,
    }


def _mb(nbytes) -> str:
    return "n/a" if nbytes is None else f"{nbytes / 2**20:,.1f} MB"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument(
        "--edges",
        nargs="+",
        type=int,
        default=[100, 300, 1000, 3000, 10000, 20000, 60016],
        help="edge counts of the triangle maps (60,016: 20,000 triangles and the walls)",
    )
    parser.add_argument("--polygon-vertices", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=1, help="builds timed per map (best)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, float64, CPU")

    originals = (load_map("pinball_hard_single"), load_map("pinball_simple_single"))
    rows = [(m.name, m) for m in originals]
    rows += [("triangles", triangles_map(n)) for n in args.edges]
    rows += [("polygon", polygon_map(args.polygon_vertices + 16))]
    CollisionGrid.build(rows[0][1])  # warm-up: first calls pay torch's one-off costs
    results = [(label, measure(m, args.repeat)) for label, m in rows]
    ref = results[0][1]
    print(
        "\n| map | edges | entries | entries / edge | build | peak | peak / edge | estimate "
        "| old dense | build vs hard | peak vs hard |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, r in results:
        per_edge = "n/a" if r["peak"] is None else f"{r['peak'] / r['edges'] / 1024:,.1f} KB"
        peak_ratio = (
            "n/a" if r["peak"] is None or not ref["peak"] else f"{r['peak'] / ref['peak']:.1f}x"
        )
        print(
            f"| {label} | {r['edges']:,} | {r['entries']:,} | {r['entries'] / r['edges']:.0f} | "
            f"{r['build']:.3f} s | {_mb(r['peak'])} | {per_edge} | {_mb(r['estimate'])} | "
            f"{_mb(r['dense'])} | {r['build'] / ref['build']:.1f}x | {peak_ratio} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
