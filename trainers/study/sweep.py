"""``skillchain sweep SPEC``: a grid of runs (agents x maps x any TrainConfig field x seeds).

SPEC (TOML, or YAML when PyYAML is installed) holds ``[base]``, the ``TrainConfig`` fields
of every cell, and ``[grid]``, lists of values whose every combination is a cell; a list of
seeds gives blocks of seeds (``seed = [0, 100]``: agents 0..runs-1 and 100..). Optional
top-level keys: ``out``, ``workers``, ``block_size``; optional ``[summary] windows``, 1-based
inclusive episode windows of the table (default: the first and last tenth of the episodes).

Each cell is a normal run directory, ``OUT/<cell>/`` (named by its grid values), trained as a
sharded run (as ``skillchain train --workers`` runs one): the blocks of every cell share one
Ray pool, so the workers stay busy across cells. A re-run skips complete cells
(``returns.npy`` present and ``config.json`` the cell's config) and resumes unfinished ones.
Then ``OUT/summary.md`` (per cell: window means with 95% t intervals, and each window's
difference from the first cell) and ``OUT/summary.png`` (mean curves with 95% bands) compare
them.

Fields an agent does not read (``UNREAD_FIELDS``, e.g. ``slots`` for ``flat``) are left at
their defaults in that agent's cells, so such a grid gives each of them once.

Example spec:
    [base]
    runs = 10
    episodes = 100
    [grid]
    agent = ["flat", "skill-chaining"]
    alpha = [0.001, 0.0005]
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.config.config import UNREAD_FIELDS, TrainConfig

__all__ = ["load_spec", "expand_grid", "cell_complete", "summary_table", "run_sweep"]

SPEC_KEYS = ("out", "workers", "block_size", "base", "grid", "summary")


def load_spec(path: str | Path) -> dict:
    """Read a TOML (``.toml``) or YAML (``.yaml``/``.yml``) sweep spec; ``ValueError`` names
    the file and what is wrong with it."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise ValueError(f"{path}: cannot read the sweep spec ({err.strerror or err})") from None
    loads, error, kind = _parser(path)
    try:
        spec = loads(text)
    except error as err:
        raise ValueError(f"{path}: not valid {kind} ({' '.join(str(err).split())})") from None
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: a sweep spec is a table with [base] and [grid]")
    unknown = sorted(set(spec) - set(SPEC_KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown keys {', '.join(unknown)} (expected "
                         f"{', '.join(SPEC_KEYS)})")  # fmt: skip
    for key in ("base", "grid", "summary"):
        if not isinstance(spec.get(key, {}), dict):
            raise ValueError(f"{path}: [{key}] must be a table")
    for name, values in spec.get("grid", {}).items():
        if not isinstance(values, list) or not values:
            raise ValueError(f"{path}: grid field {name!r} must be a non-empty list, got "
                             f"{values!r}")  # fmt: skip
    return spec


def _parser(path: Path):
    """``(loads, the error it raises, format name)`` for ``path``'s suffix."""
    if path.suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise ValueError(f"{path}: YAML specs need PyYAML (pip install pyyaml); or "
                             f"write it as TOML") from None  # fmt: skip
        return yaml.safe_load, yaml.YAMLError, "YAML"
    try:
        import tomllib
    except ImportError:  # Python 3.10
        raise ValueError(f"{path}: TOML specs need Python 3.11 or later (tomllib); write it "
                         f"as YAML") from None  # fmt: skip
    return tomllib.loads, tomllib.TOMLDecodeError, "TOML"


def _cell_name(values: dict) -> str:
    """``agent-flat__alpha-0.001``: the grid values of a cell, safe as a directory name."""
    if not values:
        return "base"
    parts = (f"{k}-{v}" for k, v in values.items())
    return "__".join(parts).replace("/", "_").replace(" ", "_")


def expand_grid(spec: dict, source: str = "spec") -> list[tuple[str, TrainConfig]]:
    """Every cell of the grid, ``(name, validated and resolved config)``, in grid order.

    Example:
        >>> cells = expand_grid({"base": {"runs": 2}, "grid": {"agent": ["flat"],
        ...                                                      "seed": [0, 10]}})
        >>> [(name, cfg.seed) for name, cfg in cells]
        [('agent-flat__seed-0', 0), ('agent-flat__seed-10', 10)]
    """
    base, grid = dict(spec.get("base", {})), dict(spec.get("grid", {}))
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    for section, fields in (("base", base), ("grid", grid)):
        unknown = sorted(set(fields) - names)
        if unknown:
            raise ValueError(f"{source}: [{section}] has unknown TrainConfig fields "
                             f"{', '.join(unknown)}")  # fmt: skip
    cells: dict[str, TrainConfig] = {}
    for combo in itertools.product(*grid.values()):
        values = dict(zip(grid, combo))
        agent = values.get("agent", base.get("agent", TrainConfig.agent))
        unread = set(UNREAD_FIELDS.get(agent, ()))
        fields = {k: v for k, v in {**base, **values}.items() if k not in unread}
        shown = {k: v for k, v in values.items() if k not in unread}
        name = _cell_name(shown)
        try:
            cells[name] = TrainConfig(**fields).validate().resolved()
        except ValueError as err:
            raise ValueError(f"{source}: cell {name}: {' '.join(str(err).split())}") from None
    return list(cells.items())


def cell_complete(cell_dir: Path, config: TrainConfig) -> bool:
    """The cell's run is finished and is this config's (a changed spec re-runs nothing
    silently: see :func:`run_sweep`)."""
    if not (cell_dir / "returns.npy").is_file() or not (cell_dir / "config.json").is_file():
        return False
    return not TrainConfig.load_json(cell_dir / "config.json").mismatches(config)


def default_windows(episodes: int) -> list[tuple[int, int]]:
    """The first and last tenth of ``episodes`` (1-based, inclusive).

    Example:
        >>> default_windows(100)
        [(1, 10), (91, 100)]
    """
    tenth = max(1, episodes // 10)
    return [(1, tenth), (episodes - tenth + 1, episodes)]


def summary_table(cells: list[tuple[str, np.ndarray]], windows) -> str:
    """Markdown: per cell its runs and, per window, the mean return over runs +- the 95% t
    interval, and (second cell on) the difference from the first cell (Welch's t interval;
    ``*`` when it excludes 0; :mod:`.intervals`).

    Example:
        >>> rng = np.random.default_rng(0)
        >>> print(summary_table([("a", rng.normal(size=(5, 4))), ("b", rng.normal(size=(5, 4)))],
        ...                     [(1, 2)]).splitlines()[0])
        | cell | runs | episodes 1-2 | 1-2 vs a |
    """
    from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci
    from skillchain_torch.trainers.study.paper_report import window

    first_name, first = cells[0]
    head = ["cell", "runs"] + [f"episodes {a}-{b}" for a, b in windows]
    head += [f"{a}-{b} vs {first_name}" for a, b in windows] if len(cells) > 1 else []
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, returns in cells:
        row = [name, str(returns.shape[0])]
        row += ["{:,.0f} ± {:,.0f}".format(*mean_ci(window(returns, a, b))) for a, b in windows]
        if len(cells) > 1:
            for a, b in windows:
                if name == first_name:
                    row.append("")
                    continue
                d, half = diff_ci(window(returns, a, b), window(first, a, b))
                row.append(f"{d:+,.0f} ± {half:,.0f}" + (" *" if abs(d) > half else ""))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def save_sweep_figure(cells: list[tuple[str, np.ndarray]], path: Path) -> Path:
    """Every cell's mean return per episode with its 95% band, on one axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from skillchain_torch.trainers.outputs.plots import plot_learning_curve

    fig = Figure(figsize=(8, 5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for name, returns in cells:
        plot_learning_curve(returns, ax=ax, label=name)
    handles, labels = ax.get_legend_handles_labels()  # one entry per cell, not per band
    keep = [i for i, label in enumerate(labels) if label != "95% interval"]
    ax.legend([handles[i] for i in keep], [labels[i] for i in keep], loc="lower right",
              fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


def run_sweep(spec_path: str | Path, out: str | Path | None = None, workers: int | None = None,
              block_size: int | None = None, address: str | None = None,
              quiet: bool = False) -> dict:
    """Run the sweep of ``spec_path`` (arguments override the spec's keys); returns
    ``{"cells", "ran", "skipped", "summary"}`` (names and the summary's path).

    ``ValueError`` (one line) for a bad spec, or a cell directory holding another config.
    """
    import os

    from skillchain_torch.trainers.distributed.blocks import ShardedRun, plan_blocks
    from skillchain_torch.trainers.distributed.ray_runs import run_sharded

    spec = load_spec(spec_path)
    cells = expand_grid(spec, str(spec_path))
    out = Path(out if out is not None else spec.get("out") or Path(spec_path).stem)
    workers = int(workers or spec.get("workers") or os.cpu_count() or 1)
    size = block_size or spec.get("block_size")
    if workers < 1 or (size is not None and size != "shrink" and int(size) < 1):
        raise ValueError(f"{spec_path}: workers and block_size must be >= 1")
    todo, skipped = [], []
    for name, config in cells:
        cell_dir = out / name
        if cell_complete(cell_dir, config):
            skipped.append(name)
            continue
        saved = cell_dir / "config.json"
        if saved.is_file() and TrainConfig.load_json(saved).mismatches(config):
            raise ValueError(f"{cell_dir} holds a run of another config (fields "
                             f"{', '.join(TrainConfig.load_json(saved).mismatches(config))}); "
                             f"remove it or choose another --out")  # fmt: skip
        cell_dir.mkdir(parents=True, exist_ok=True)
        if (cell_dir / "sharding.json").is_file():  # interrupted: resume its blocks
            todo.append(ShardedRun.load(cell_dir, config))
            continue
        config.save_json(saved)
        per = None if size is None else min(int(size), config.runs)
        run = ShardedRun(config, cell_dir, plan_blocks(config.runs, workers, per))
        run.save(workers)
        todo.append(run)
    if not quiet and skipped:
        print(f"skipped {len(skipped)} complete cell{'s' * (len(skipped) != 1)}: "
              + ", ".join(skipped), flush=True)
    if todo:
        run_sharded(todo, workers, address=address, quiet=quiet)
    results = [(name, np.load(out / name / "returns.npy")) for name, _ in cells]
    windows = spec.get("summary", {}).get("windows")
    windows = ([tuple(w) for w in windows] if windows
               else default_windows(min(r.shape[1] for _, r in results)))
    table = summary_table(results, windows)
    header = (f"# Sweep {Path(spec_path).name}\n\nMean return per run over each window, with "
              f"its 95% t interval over runs; 'vs' columns: the difference from the first cell "
              f"(Welch's 95% t interval; * when it excludes 0).\n\n")
    summary = out / "summary.md"
    summary.write_text(header + table + "\n\n![curves](summary.png)\n")
    save_sweep_figure(results, out / "summary.png")
    (out / "sweep.json").write_text(json.dumps(
        {"spec": str(spec_path), "cells": [n for n, _ in cells], "workers": workers}) + "\n")
    return {"cells": [n for n, _ in cells], "ran": [r.out.name for r in todo],
            "skipped": skipped, "summary": summary, "table": table}
