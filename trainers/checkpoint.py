"""Checkpoints of a :class:`~.population.PopulationTrainer`: save, find, validate, load.

A checkpoint is ``torch.save`` of a dict with ``format_version``, the run ``config`` and the
trainer's ``state_dict``: the agents' weights, random-stream seeds and counters, the
environments' raw states, step counters and start streams, the active agents' current features
and decisions, partial returns and lengths, the returns/lengths arrays so far and the episode
counters. Everything is a tensor or a plain Python value, so it loads with
``torch.load(weights_only=True)``. A run resumed from a checkpoint continues bit for bit as if
it had never stopped.

Example:
    >>> import tempfile
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> out = tempfile.mkdtemp()
    >>> cfg = TrainConfig(runs=2, episodes=1, max_episode_steps=3)
    >>> path = PopulationTrainer(cfg, out_dir=out).train().checkpoint_path()
    >>> restored = PopulationTrainer(cfg, out_dir=out)
    >>> load_checkpoint(path, restored)
    >>> restored.lengths.tolist()
    [[3], [3]]
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import torch

from .config import TrainConfig

__all__ = ["FORMAT_VERSION", "save_checkpoint", "read_checkpoint", "load_checkpoint",
           "latest_checkpoint"]

FORMAT_VERSION = 1
_NAME = re.compile(r"ckpt_(\d+)\.pt$")
_SECTIONS = {
    "agent": ("q_head", "rng", "index", "action", "phi"),
    "env": ("state", "step_count", "done", "rng", "seed", "index"),
    "trainer": ("returns", "lengths", "episodes_done", "partial_return", "partial_length",
                "global_step", "agent_steps", "elapsed", "started", "next_checkpoint"),
}


def save_checkpoint(trainer, path: str | Path) -> Path:
    """Write ``trainer``'s state to ``path`` atomically (a temporary file, then a rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format_version": FORMAT_VERSION, **trainer.state_dict()}
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def read_checkpoint(path: str | Path) -> dict:
    """Load and check the structure of a checkpoint; ``ValueError`` naming the file and field."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint file")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for truncated or foreign files
        raise ValueError(f"{path}: not a readable checkpoint ({type(err).__name__}: {err})") \
            from None
    if not isinstance(state, dict) or "format_version" not in state:
        raise ValueError(f"{path}: not a skillchain checkpoint (field 'format_version' missing)")
    version = state["format_version"]
    if version != FORMAT_VERSION:
        raise ValueError(
            f"{path}: field 'format_version' is {version!r}, but this code reads version "
            f"{FORMAT_VERSION}"
        )
    for field in ("config", *_SECTIONS, "modules"):
        if not isinstance(state.get(field), dict):
            raise ValueError(f"{path}: field {field!r} is missing or not a dict")
    for section, keys in _SECTIONS.items():
        for key in keys:
            if key not in state[section]:
                raise ValueError(f"{path}: field '{section}.{key}' is missing")
    try:
        state["config"] = TrainConfig.from_dict(state["config"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: field 'config' is invalid ({err})") from None
    return state


def load_checkpoint(path: str | Path, trainer) -> None:
    """Restore ``trainer`` from ``path``; its config must match the checkpoint's.

    Only ``checkpoint_every`` and ``device`` may differ. A mismatch (e.g. another map, number
    of runs or seed) raises ``ValueError`` naming the file and the field.
    """
    state = read_checkpoint(path)
    saved: TrainConfig = state["config"]
    for field in saved.mismatches(trainer.config):
        raise ValueError(
            f"{path}: config field {field!r} is {getattr(saved.resolved(), field)!r} in the "
            f"checkpoint but {getattr(trainer.config, field)!r} in this trainer"
        )
    state["config"] = saved.to_dict()
    try:
        trainer.load_state_dict(state)
    except (KeyError, RuntimeError, IndexError) as err:
        raise ValueError(f"{path}: inconsistent checkpoint contents ({err})") from None
    except ValueError as err:  # e.g. saved by the other flat-agent kernel
        raise ValueError(f"{path}: {err}") from None


def latest_checkpoint(directory: str | Path) -> Path | None:
    """The checkpoint with the most completed episodes under ``directory`` (or its
    ``checkpoints/`` folder); ``None`` if there is none."""
    directory = Path(directory)
    if (directory / "checkpoints").is_dir():
        directory = directory / "checkpoints"
    found = [(int(m.group(1)), p) for p in directory.glob("ckpt_*.pt")
             if (m := _NAME.search(p.name))]
    return max(found)[1] if found else None
