"""The one switch between the torch path and a compiled kernel.

Two kinds of kernel, one place that chooses:

* kernels that give the torch path's bits (FourierBasis's features, CounterRNG's draws, skill
  chaining's bookkeeping: :mod:`.fourier`, :mod:`.rng`, :mod:`.discovery`) leave nothing to
  choose: they run wherever built, on CPU tensors; :func:`same_bits_kernels` turns them off
  (tests and benchmarks compare the two paths);
* kernels that sum in an order of their own (the hierarchical agent's step, the initiation
  classifier: :mod:`.hierarchical`, :mod:`.initiation`) are the user's choice (``native``),
  made by :func:`compiled` and only for pieces that are exactly the built-in classes
  (:func:`builtin_type_problems`).

Example:
    >>> from skillchain_torch.options import InitiationClassifier
    >>> class Mine(InitiationClassifier):
    ...     pass
    >>> clf = Mine(population=1, slots=1, capacity=4)
    >>> builtin_type_problems({"the initiation classifier": (clf, InitiationClassifier)})
    ['the initiation classifier is Mine, not the built-in InitiationClassifier']
    >>> compiled(None, {"built": True}, [])
    True
    >>> compiled(True, {"built": False}, ["the option head is Mine, not ..."])
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: the compiled path cannot run: it needs built; the option head is Mine, ...
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator, Mapping, Sequence

import torch

from skillchain_torch.backends.native import check_same_kernels  # (a saved state's kind)

# The one switch of the kernels that give the torch path's bits (features, draws, discovery's
# bookkeeping): on, unless a comparison turns it off for a block (same_bits_kernels). A context
# variable, read only when a piece or an agent is built.
_SAME_BITS = contextvars.ContextVar("same_bits_kernels", default=True)

__all__ = ["builtin_type_problems", "check_same_kernels", "compiled", "discovery_rules",
           "flat_step", "hierarchical_step", "initiation_kernel", "same_bits_kernel",
           "same_bits_kernels"]


def builtin_type_problems(pieces: Mapping[str, tuple[object, type]]) -> list[str]:
    """One sentence per piece that is not exactly its built-in class (``{name: (piece,
    builtin)}``): a subclass may override any method, which a kernel would not run."""
    return [f"{name} is {type(piece).__name__}, not the built-in {builtin.__name__}"
            for name, (piece, builtin) in pieces.items() if type(piece) is not builtin]


def compiled(native: bool | None, needs: Mapping[str, bool],
             problems: Sequence[str] = ()) -> bool:  # fmt: skip
    """Whether to run a compiled kernel.

    Args:
        native: the user's choice: ``None`` (the kernel where it applies), ``True`` (the
            kernel, or an error), ``False`` (the torch path).
        needs: ``{what the kernel needs: whether it holds}`` (built, the CPU, float64, ...).
        problems: pieces that are not the built-ins the kernel replaces
            (:func:`builtin_type_problems`).

    Returns:
        ``True`` for the kernel. Raises ``ValueError`` (one line, naming every missing need and
        every piece) when ``native`` is ``True`` and the kernel cannot run.
    """
    missing = [f"it needs {name}" for name, ok in needs.items() if not ok] + list(problems)
    if native and missing:
        raise ValueError(f"the compiled path cannot run: {'; '.join(missing)}; use "
                         "native=False (or leave it None) to take the torch path")
    return not missing if native is None else bool(native)


def hierarchical_step(native: bool | None, **pieces):
    """The hierarchical agent's compiled step (:class:`~.compiled_step.CompiledStep`) or
    ``None`` (the torch path), chosen once when the agent is built: ``native`` as
    :func:`compiled` reads it, for the pieces :func:`~.hierarchical.resolve` checks
    (``option_head``, ``top_head``, ``top_features``, ``device``, ``obs_dim``,
    ``num_primitives``, ``completion_reward``); ``native=True`` with a piece of the user's own
    is a ``ValueError`` naming it."""
    from skillchain_torch.backends import hierarchical

    if not hierarchical.resolve(native, **pieces):
        return None
    from skillchain_torch.backends.compiled_step import CompiledStep

    return CompiledStep()


def initiation_kernel(classifier, native: bool | None):
    """The initiation classifier's compiled memberships, fits and stores
    (:class:`~.compiled_initiation.CompiledInitiation`) or ``None`` (its torch path):
    ``native`` as :func:`compiled` reads it, for a classifier that is exactly the built-in
    :class:`~skillchain_torch.options.InitiationClassifier` (a subclass may change any rule,
    which C would not run), with 4-d observations, on the CPU in float64. The hierarchical
    agent asks once, when it is built (``InitiationClassifier.set_native``).

    Example:
        >>> from skillchain_torch.options import InitiationClassifier
        >>> initiation_kernel(InitiationClassifier(population=1, slots=1), False) is None
        True
    """
    from skillchain_torch.backends import initiation
    from skillchain_torch.options.initiation import InitiationClassifier

    w = classifier.weight
    if not compiled(native, {
        "the compiled classifier (built)": initiation.AVAILABLE,
        f"a {initiation.OBS_DIM}-d observation": classifier.obs_dim == initiation.OBS_DIM,
        f"the classifier on the CPU in float64 (it is on {w.device}, {w.dtype})":
            w.device.type == "cpu" and w.dtype == torch.float64,
    }, builtin_type_problems({"the initiation classifier": (classifier, InitiationClassifier)})):
        return None
    from skillchain_torch.backends.compiled_initiation import CompiledInitiation

    return CompiledInitiation(classifier.distance_dims)


def same_bits_kernel(name: str):
    """The kernel that gives the torch path's bits for a built-in piece, chosen when the piece
    is built: ``"fourier"`` (FourierBasis's features) or ``"rng"`` (CounterRNG's draws); ``None``
    where it is not built or :func:`same_bits_kernels` has it off. The piece keeps the answer,
    so a piece built with it off stays on the torch path.

    Example:
        >>> with same_bits_kernels(False):
        ...     same_bits_kernel("fourier") is None
        True
    """
    from skillchain_torch.backends import fourier, rng

    module = {"fourier": fourier, "rng": rng}[name]
    if not (_SAME_BITS.get() and module.AVAILABLE):
        return None
    return module.features if name == "fourier" else module.draw


def flat_step(native: bool | None, device, obs_dim: int | None, num_actions: int | None):
    """The flat Sarsa agent's compiled step (:class:`~.compiled_sarsa.CompiledSarsaStep`) or
    ``None`` (the torch path), chosen once when the agent is built: ``native`` as
    :func:`compiled` reads it, for the CPU and Pinball's 4-d observation and 5 actions."""
    from skillchain_torch.backends import sarsa

    if not compiled(native, {
        "the compiled kernels (built)": sarsa.AVAILABLE,
        f"the CPU (got {device})": device.type == "cpu",
        "Pinball's 4-d observation and 5 actions":
            obs_dim in (None, 4) and num_actions in (None, 5),
    }):
        return None
    from skillchain_torch.backends.compiled_sarsa import CompiledSarsaStep

    return CompiledSarsaStep()


def discovery_rules(native: bool) -> type:
    """Skill chaining's rules for an agent whose step is compiled (``native``) or not: the
    torch path's :class:`~skillchain_torch.discovery.SkillChaining`, or, for a compiled step
    where the kernels are built, its subclass with the per-step bookkeeping compiled (the same
    bits, :class:`~.compiled_discovery.CompiledSkillChaining`). Chosen once, when the agent
    is built.

    Example:
        >>> discovery_rules(False).__name__
        'SkillChaining'
    """
    from skillchain_torch.backends import discovery as kernels
    from skillchain_torch.discovery.skill_chaining import SkillChaining

    if not (native and kernels.AVAILABLE and _SAME_BITS.get()):  # (not off for a comparison)
        return SkillChaining
    from skillchain_torch.backends.compiled_discovery import CompiledSkillChaining

    return CompiledSkillChaining


@contextlib.contextmanager
def same_bits_kernels(on: bool) -> Iterator[None]:
    """Within the block, pieces and agents built take the kernels that give the torch path's
    bits (features, draws, discovery's bookkeeping) where built (``on``) or not at all (the
    torch path everywhere), and the Pinball step runs its compiled physics or not (the env's
    own switch); as they were after it. Pieces keep what they took when built.

    Example:
        >>> with same_bits_kernels(False):
        ...     same_bits_kernel("rng") is None
        True
    """
    from skillchain_torch.envs.pinball import native as pinball_native
    from skillchain_torch.envs.pinball import physics  # the env's own fast path

    token, saved = _SAME_BITS.set(bool(on)), physics.NATIVE
    physics.NATIVE = on and pinball_native.AVAILABLE
    try:
        yield
    finally:
        _SAME_BITS.reset(token)
        physics.NATIVE = saved
