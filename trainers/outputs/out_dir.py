"""The command line's ``--out`` folder: refused in one line when it cannot take the run, made
(or a previous run's outputs cleared, with ``--overwrite``), and removed again when a run that
created it fails before writing anything.

Example:
    >>> import argparse, tempfile
    >>> from pathlib import Path
    >>> folder = Path(tempfile.mkdtemp()) / "new" / "run"
    >>> _check_out(argparse.ArgumentParser(), folder, overwrite=False)   # can be created: ok
    >>> _prepare_out(argparse.ArgumentParser(), folder, overwrite=False).name
    'new'
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from skillchain_torch.trainers.outputs.run_outputs import OUTPUTS

__all__ = ["_check_out", "_fail", "_prepare_out", "_remove_created", "_remove_outputs"]


def _fail(parser, message: str) -> None:
    """Exit with status 2 and one line (for failures that are not about the arguments' form)."""
    parser.exit(2, f"{parser.prog}: error: {message}\n")


def _check_out(parser, out: Path, overwrite: bool) -> None:
    """Refuse an ``--out`` that cannot take the run, writing nothing."""
    try:
        if out.exists() and not out.is_dir():
            parser.error(f"--out {out} exists and is not a directory")
        if out.is_dir():
            if any(out.iterdir()) and not overwrite:
                parser.error(
                    f"--out {out} exists and is not empty; pass --resume {out} to continue "
                    "it or --overwrite to replace it"
                )
            if not os.access(out, os.W_OK | os.X_OK):
                parser.error(f"--out {out}: the directory is not writable")
            return
        parent = next(p for p in out.absolute().parents if p.exists())
    except OSError as err:
        parser.error(f"--out {out}: cannot use it ({err.strerror or err})")
    if not parent.is_dir():
        parser.error(f"--out {out}: {parent} is a file, so no directory can be created under it")
    if not os.access(parent, os.W_OK | os.X_OK):
        parser.error(f"--out {out}: cannot create it, {parent} is not writable")


def _prepare_out(parser, out: Path, overwrite: bool) -> Path | None:
    """Create ``out`` (or clear a previous run's outputs from it, with ``overwrite``); returns
    the topmost directory this call created (``None`` if ``out`` existed)."""
    missing = [p for p in (out.absolute(), *out.absolute().parents) if not p.exists()]
    created = missing[-1] if missing else None
    try:
        if out.is_dir() and any(out.iterdir()) and overwrite:
            _remove_outputs(out, strict=True)
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        _remove_created(created)
        _fail(parser, f"--out {out}: cannot write there ({err.strerror or err})")
    return created


def _remove_created(created: Path | None) -> None:
    if created is not None:
        shutil.rmtree(created, ignore_errors=True)


def _remove_outputs(out: Path, strict: bool = False) -> None:
    """Remove a run's outputs (``OUTPUTS``) from ``out``; ``strict``: raise ``OSError``s."""
    for name in OUTPUTS:
        target = out / name
        try:
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
        except OSError:
            if strict:
                raise
