"""Saving and loading option banks: torch files read safely, digests, and the registry of the
classes a bank's parts are rebuilt from.

A bank file records its parts by class name; :meth:`OptionBank.load` rebuilds them from
:data:`Q_HEADS` and :data:`CLASSIFIERS`. A researcher's own option head or initiation set
registers once (:func:`register_q_head`, :func:`register_classifier`, usable as decorators)
and then loads like the built-ins; an unregistered name is a one-line error that says so.

Example:
    >>> from skillchain_torch.options import InitiationClassifier
    >>> @register_classifier
    ... class Wider(InitiationClassifier):
    ...     pass
    >>> CLASSIFIERS["Wider"] is Wider
    True
    >>> lookup(CLASSIFIERS, "Nope", "initiation classifier", "register_classifier")
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    skillchain_torch.options.io.Unregistered: initiation classifier class 'Nope' is not ...
"""

from __future__ import annotations

import hashlib
import math
import os
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from skillchain_torch.options.initiation import InitiationClassifier
from skillchain_torch.options.mlp_initiation import MLPInitiationClassifier
from skillchain_torch.options.mlp_q_head import MLPOptionQHead
from skillchain_torch.options.q_head import FourierOptionQHead, OptionQHead

__all__ = ["CLASSIFIERS", "Q_HEADS", "Unregistered", "content_digest", "lookup", "read_torch_file",
           "register_classifier", "register_q_head"]

_ZIP, _PICKLE = b"PK\x03\x04", b"\x80"  # how torch.save's files (zip, legacy pickle) start

Q_HEADS: dict[str, type[OptionQHead]] = {
    "FourierOptionQHead": FourierOptionQHead,
    "MLPOptionQHead": MLPOptionQHead,
}
CLASSIFIERS: dict[str, type] = {"InitiationClassifier": InitiationClassifier,
                                 "MLPInitiationClassifier": MLPInitiationClassifier}


def register_q_head(cls: type[OptionQHead]) -> type[OptionQHead]:
    """Let :meth:`OptionBank.load` rebuild option heads of class ``cls`` (by its name, from
    its ``config``). Returns ``cls``, so it works as a decorator."""
    if not (isinstance(cls, type) and issubclass(cls, OptionQHead)):
        raise TypeError(f"register_q_head takes an OptionQHead subclass, got {cls!r}")
    Q_HEADS[cls.__name__] = cls
    return cls


def register_classifier(cls: type) -> type:
    """Let :meth:`OptionBank.load` rebuild initiation sets of class ``cls`` (by its name, from
    its ``config``). Returns ``cls``, so it works as a decorator."""
    if not isinstance(cls, type):
        raise TypeError(f"register_classifier takes a class, got {cls!r}")
    CLASSIFIERS[cls.__name__] = cls
    return cls


class Unregistered(ValueError):
    """A bank part's class that is not in its registry."""


def lookup(registry: dict[str, type], name: str, what: str, register: str) -> type:
    """``registry[name]``, or a one-line ``ValueError`` saying how to register it."""
    if name not in registry:
        raise Unregistered(f"{what} class {name!r} is not registered (known: "
                         f"{', '.join(sorted(registry))}): call skillchain_torch.options."
                         f"{register}({name}) before loading, or pass the part in")  # fmt: skip
    return registry[name]


def read_torch_file(path: str | os.PathLike, what: str) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU; every failure is a ``ValueError`` of
    one line, ``"{path}: not a readable {what} ({reason})"``, that says what the file is
    instead (missing, a directory, empty, not a torch file, truncated or damaged, or holding
    Python objects a weights-only load refuses). Torch's own warnings are not shown."""
    path = Path(path)
    head: bytes | None = None
    if not path.exists():
        reason = "no such file"
    elif path.is_dir():
        reason = "it is a directory"
    else:
        try:
            with open(path, "rb") as f:
                head = f.read(4)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return torch.load(path, map_location="cpu", weights_only=True)
        except Exception as error:  # torch raises many types for truncated or foreign files
            reason = _unreadable(head, error)
    raise ValueError(f"{path}: not a readable {what} ({reason})")


def content_digest(value: Any) -> str:
    """The sha256 (hex) of a saved structure: each tensor's dtype, shape and bytes (on the
    CPU), each plain value's type and ``repr``, dicts and sequences in order. Equal for the
    structure saved and the one ``torch.load`` gives back, so it detects altered files."""
    digest = hashlib.sha256()
    _feed(digest, value)
    return digest.hexdigest()


def _feed(digest, value: Any) -> None:
    if isinstance(value, Tensor):
        t = value.detach().cpu().contiguous()
        digest.update(f"T{t.dtype}{tuple(t.shape)}|".encode())
        if t.numel():
            digest.update(t.reshape(-1).view(torch.uint8).numpy())
    elif isinstance(value, dict):
        digest.update(f"D{len(value)}|".encode())
        for key, item in value.items():
            _feed(digest, key)
            _feed(digest, item)
    elif isinstance(value, (list, tuple)):
        digest.update(f"L{len(value)}|".encode())
        for item in value:
            _feed(digest, item)
    else:  # None, bool, int, float, str
        text = repr(value)
        digest.update(f"{type(value).__name__}{len(text)}|{text}".encode())


def _unreadable(head: bytes | None, error: Exception) -> str:
    """Why ``torch.load`` failed, in one short line."""
    first = " ".join(str(error).split(". ")[0].split())[:160] or type(error).__name__
    if head is None:
        return first
    if not head:
        return "the file is empty"
    if not head.startswith((_ZIP, _PICKLE)):
        return f"not a torch file: it starts with {head!r}"
    text = str(error)
    if "Unsupported global" in text:
        name = text.split("Unsupported global:", 1)[1].split()[1:2]
        return (f"it holds Python objects ({', '.join(name) or 'a global'}) that a weights-only "
                f"load refuses")  # fmt: skip
    if "Weights only load failed" in text:  # e.g. a plain pickle, not torch.save's format
        return "not a torch file, or a damaged one: the unpickler refused it"
    return f"a truncated or damaged torch file: {first}"


class _NonFinite(ValueError):
    pass


def _check_finite(state: dict, population: int) -> None:
    """``_NonFinite`` naming the first floating tensor of ``state`` with NaN or inf values."""
    for key, value in state.items():
        if not (isinstance(value, Tensor) and value.is_floating_point()):
            continue
        if math.isfinite(float(value.sum())):  # one pass when all is well
            continue
        bad = ~torch.isfinite(value)
        if not bool(bad.any()):  # a finite sum that overflowed
            continue
        where = ""
        if value.dim() >= 1 and value.shape[0] == population:
            agents = bad.reshape(population, -1).any(-1).nonzero().flatten().tolist()
            where = f" (agents {agents})"
        raise _NonFinite(f"tensor {key!r} holds {int(bad.sum())} NaN or infinite "
                         f"values{where}")  # fmt: skip
