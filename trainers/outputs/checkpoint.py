"""Checkpoints of a :class:`~.population.PopulationTrainer`: save, find, validate, load.

A checkpoint is ``torch.save`` of a dict with ``format_version``, the run ``config`` and the
trainer's ``state_dict``: the agents' weights, random-stream seeds and counters, the
environments' raw states, step counters and start streams, the active agents' current features
and decisions, partial returns and lengths, the returns/lengths arrays so far and the episode
counters. Everything is a tensor or a plain Python value, so it loads with
``torch.load(weights_only=True)``. A run resumed from a checkpoint continues bit for bit as if
it had never stopped.

Integrity: a checkpoint also holds ``sha256``, a digest of everything else it holds (the
tensors' bytes, dtypes and shapes, and the plain values), which :func:`read_checkpoint`
verifies; a file whose bytes were altered, or a truncated one, raises
:class:`DamagedCheckpoint`. Checkpoints written before the digest (no ``sha256``) load
unverified. :func:`save_checkpoint` writes a temporary file, reads it back and verifies it
before it replaces anything, and every checkpoint is kept (``ckpt_{episodes}.pt``; with
``keep_checkpoints`` the newest few and the one a longer run extends from), so a failed write
loses none. :func:`resume_checkpoint` loads the newest checkpoint that verifies,
moving damaged newer ones aside (``NAME.damaged``) with a warning that names them.

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

import logging
import os
import re
from pathlib import Path

import torch

from skillchain_torch.options.io import content_digest, read_torch_file
from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["FORMAT_VERSION", "save_checkpoint", "read_checkpoint", "load_checkpoint",
           "latest_checkpoint", "resume_checkpoint", "extend_run", "payload_digest",
           "DamagedCheckpoint"]

logger = logging.getLogger(__name__)

FORMAT_VERSION = 1  # the digest is an optional field: files with it still read as version 1
CHECKSUM = "sha256"
_NAME = re.compile(r"ckpt_(\d+)\.pt$")
_SECTIONS = {
    "agent": ("q_head", "rng", "index", "action", "phi"),
    "env": ("state", "step_count", "done", "rng", "seed", "index"),
    "trainer": ("returns", "lengths", "episodes_done", "partial_return", "partial_length",
                "global_step", "agent_steps", "elapsed", "started", "next_checkpoint"),
}


# The env section of the steppers other than Pinball's: EnvStepper (a Gymnasium/TorchRL env's
# counters only) and the batched classic-control envs (envs/classic.py: their whole state).
_ENV_KINDS = {"torchrl-envs": ("index", "step_count"),
              "mountain-car": ("index", "step_count", "position", "velocity", "rngs"),
              "acrobot": ("index", "step_count", "state", "rngs"),
              "cart-pole": ("index", "step_count", "state", "rngs")}


class DamagedCheckpoint(ValueError):
    """A checkpoint file that cannot be trusted: unreadable, truncated, not a checkpoint,
    missing fields, or failing its digest (as opposed to one of another version or config)."""


def payload_digest(state: dict) -> str:
    """The sha256 (hex) of ``state`` without its ``sha256`` field (see
    :func:`~skillchain_torch.options.io.content_digest`)."""
    return content_digest({k: v for k, v in state.items() if k != CHECKSUM})


def save_checkpoint(trainer, path: str | Path) -> Path:
    """Write ``trainer``'s state and its digest to ``path``: a temporary file, flushed to disk,
    read back and verified, then renamed over ``path`` (an ``OSError`` before the rename
    leaves every earlier checkpoint as it was)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format_version": FORMAT_VERSION, **trainer.state_dict()}
    payload[CHECKSUM] = payload_digest(payload)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            torch.save(payload, f)
            f.flush()
            os.fsync(f.fileno())
        read_checkpoint(tmp)
    except ValueError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(f"{path}: the checkpoint written does not read back ({err}); the "
                      f"earlier checkpoints are kept") from None  # fmt: skip
    except BaseException:  # a full disk, an interrupt: no half-written file is left
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
    try:  # the rename itself, on disk
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:  # not every file system lets a directory be synced
        pass
    return path


def read_checkpoint(path: str | Path) -> dict:
    """Load and check a checkpoint: its format version, structure and (when it has one) its
    digest. ``DamagedCheckpoint`` for a file that cannot be trusted, ``ValueError`` for one of
    another version or with an invalid config; both one line naming the file and field."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint file")
    try:
        state = read_torch_file(path, "checkpoint")
    except ValueError as err:
        raise DamagedCheckpoint(str(err)) from None
    if not isinstance(state, dict) or "format_version" not in state:
        kind = ""
        if isinstance(state, dict) and state.get("format") == "skillchain_torch.OptionBank":
            kind = "; it is an OptionBank file (for --agent given-options --options)"
        raise DamagedCheckpoint(f"{path}: not a skillchain checkpoint (field 'format_version' "
                                f"missing{kind})")  # fmt: skip
    version = state["format_version"]
    if version != FORMAT_VERSION:
        raise ValueError(
            f"{path}: field 'format_version' is {version!r}, but this code reads version "
            f"{FORMAT_VERSION}"
        )
    for field in ("config", *_SECTIONS, "modules"):
        if not isinstance(state.get(field), dict):
            raise DamagedCheckpoint(f"{path}: field {field!r} is missing or not a dict")
    # A damaged key (a flipped bit in "sha256" itself) would otherwise read as a file saved
    # before checkpoints had a digest, and skip the check: nothing else is ever saved here.
    unknown = sorted(set(state) - {"format_version", "config", *_SECTIONS, "modules", CHECKSUM})
    if unknown:
        raise DamagedCheckpoint(f"{path}: unknown field {str(unknown[0])[:40]!r}: the file was "
                                "altered or damaged after it was written")
    for section, keys in _SECTIONS.items():
        if section == "env" and state["env"].get("kind") in _ENV_KINDS:
            keys = _ENV_KINDS[state["env"]["kind"]]  # (an env stepper other than Pinball's)
        if section == "agent" and state["trainer"].get("user_agent"):
            keys = ()  # a user's agent (interfaces.EpisodeAgent) saves what it declares
        for key in keys:
            if key not in state[section]:
                raise DamagedCheckpoint(f"{path}: field '{section}.{key}' is missing")
    if CHECKSUM in state:
        stored = state[CHECKSUM]
        try:
            actual = payload_digest(state)
        except Exception as err:  # a value the digest cannot take: not what was saved
            raise DamagedCheckpoint(f"{path}: its contents cannot be digested ({err})") from None
        if stored != actual:
            raise DamagedCheckpoint(
                f"{path}: checksum mismatch (sha256 stored {str(stored)[:16]}..., contents "
                f"{actual[:16]}...): the file was altered or damaged after it was written")
    try:
        state["config"] = TrainConfig.from_dict(state["config"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: field 'config' is invalid ({err})") from None
    return state


def load_checkpoint(path: str | Path, trainer) -> None:
    """Restore ``trainer`` from ``path``; its config must match the checkpoint's.

    Only ``checkpoint_every``, ``checkpoint_minutes``, ``keep_checkpoints`` and ``device`` may
    differ. A mismatch
    (e.g. another map, number of runs or seed) raises ``ValueError`` naming the file and the
    field.
    """
    _restore(read_checkpoint(path), path, trainer)


def _restore(state: dict, path: Path, trainer, extend: bool = False) -> None:
    saved: TrainConfig = state["config"]
    for field in saved.mismatches(trainer.config):
        if extend and field == "episodes" and trainer.config.episodes >= saved.episodes:
            continue  # (extend_run: more episodes from a checkpoint before any agent finished)
        raise ValueError(
            f"{path}: config field {field!r} is {getattr(saved.resolved(), field)!r} in the "
            f"checkpoint but {getattr(trainer.config, field)!r} in this trainer"
        )
    state["config"] = saved.to_dict()
    try:
        trainer.load_state_dict(state)
    except (KeyError, RuntimeError, IndexError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: inconsistent checkpoint contents ({err})") from None
    except ValueError as err:  # e.g. saved by the other flat-agent kernel
        raise ValueError(f"{path}: {err}") from None


def resume_checkpoint(directory: str | Path, trainer) -> Path:
    """Restore ``trainer`` from the newest checkpoint under ``directory`` that verifies;
    returns its path.

    Newer checkpoints that are damaged (:class:`DamagedCheckpoint`) are renamed
    ``NAME.damaged`` once an older one has loaded (so the resumed run does not write over
    them), each with a logged warning naming it and the checkpoint used instead. Raises
    ``ValueError`` if there is no checkpoint or none verifies (naming the newest), or if the
    newest readable one does not fit ``trainer`` (another config or version: not damage,
    so no older one is tried).
    """
    found = _checkpoints(directory)
    if not found:
        raise ValueError(f"{directory}: no checkpoint under {Path(directory) / 'checkpoints'}")
    damaged: list[tuple[Path, DamagedCheckpoint]] = []
    for path in reversed(found):
        try:
            state = read_checkpoint(path)
        except DamagedCheckpoint as err:
            damaged.append((path, err))
            continue
        # A checkpoint from before any agent finished fits a run of more episodes too (an
        # extended run, interrupted: extend_run's rule).
        _restore(state, path, trainer,
                 extend=int(state["trainer"]["episodes_done"].max()) < state["config"].episodes)
        for bad, err in damaged:
            aside = bad.with_name(bad.name + ".damaged")
            os.replace(bad, aside)
            logger.warning("%s; moved aside to %s, resuming from the previous good checkpoint "
                           "%s", err, aside.name, path.name)
        return path
    more = "; no earlier checkpoint verifies either" if len(damaged) > 1 else ""
    raise ValueError(f"{damaged[0][1]}{more}")


def extend_run(directory: str | Path, trainer) -> Path:
    """Restore ``trainer``, whose config asks for more episodes than the run in ``directory``
    had, from the newest checkpoint at which no agent had yet finished its episodes (an agent
    that finished stopped for good), so the run continues exactly as a run of the new length
    would have; returns its path. The later checkpoints, of the shorter run, are moved into
    ``checkpoints/superseded/`` (an interrupted extension then resumes from its own).
    ``ValueError`` in one line when there is none."""
    path, state = extension_checkpoint(directory)
    _restore(state, path, trainer, extend=True)
    supersede_after(directory, path)
    return path


def extension_checkpoint(directory: str | Path) -> tuple[Path, dict]:
    """``(path, state)`` of the newest checkpoint under ``directory`` at which no agent had
    finished its episodes: where a longer run of the same agents would have been too.
    ``ValueError`` in one line when there is none."""
    for path in reversed(_checkpoints(directory)):
        try:
            state = read_checkpoint(path)
        except DamagedCheckpoint:
            continue
        if int(state["trainer"]["episodes_done"].max()) < state["config"].episodes:
            return path, state
    raise ValueError(f"{directory}: no checkpoint from before an agent finished its episodes, "
                     "so the run cannot be extended; train it again with more --episodes")


def supersede_after(directory: str | Path, path: Path) -> None:
    """Move the checkpoints under ``directory`` newer than ``path`` into
    ``checkpoints/superseded/`` (kept, but no longer the run's)."""
    found = _checkpoints(directory)
    later = found[found.index(path) + 1:]
    if later:
        aside = path.parent / "superseded"
        aside.mkdir(exist_ok=True)
        for old in later:
            os.replace(old, aside / old.name)


def _checkpoints(directory: str | Path) -> list[Path]:
    """The checkpoints under ``directory`` (or its ``checkpoints/`` folder), oldest first."""
    directory = Path(directory)
    if (directory / "checkpoints").is_dir():
        directory = directory / "checkpoints"
    found = [(int(m.group(1)), p) for p in directory.glob("ckpt_*.pt")
             if (m := _NAME.search(p.name))]
    return [p for _, p in sorted(found)]


def latest_checkpoint(directory: str | Path) -> Path | None:
    """The checkpoint with the most completed episodes under ``directory`` (or its
    ``checkpoints/`` folder); ``None`` if there is none."""
    found = _checkpoints(directory)
    return found[-1] if found else None
