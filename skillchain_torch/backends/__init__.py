"""Compiled accelerators of the torch path, apart from the models they serve, and the one
rule that chooses them.

A backend is never the definition of a rule: the torch path is. A model (``features/``,
``options/``, ``agents/``, ``discovery/``, ``rng.py``) reads as its rules, and its dispatch is
one call into the kernel :mod:`.select` handed it when it was built: outside this package only
:mod:`.select` is imported. :mod:`.select` is the one switch: a kernel that sums in an
order of its own runs only where every piece it replaces is *exactly* the built-in class (not
a subclass), on the CPU in float64, and built (:func:`compiled`; otherwise the torch path
runs, and asking for the kernel anyway is a ``ValueError`` naming the piece); the kernels that
give the torch path's bits run wherever built (:func:`same_bits_kernels` turns them off).

One module per concern, each with its C source beside it (``_<name>.c``, built by setup.py as
``skillchain_torch.backends._<name>``; ``AVAILABLE`` says whether it was):

======================  ======================================================================
:mod:`.fourier`         FourierBasis's features (the same bits)
:mod:`.rng`             CounterRNG's draws (the same bits)
:mod:`.discovery`       skill chaining's per-step bookkeeping (the same bits)
:mod:`.initiation`      the initiation classifier's memberships, stores and fits
                        (:class:`.compiled_initiation.CompiledInitiation` calls them)
:mod:`.hierarchical`    the hierarchical agent's whole step
:mod:`.sarsa`           the flat Sarsa agent's step
:mod:`.native`          what their Python sides share (``for_c``, the kernel kind of a state)
======================  ======================================================================

Backends take declared tensors (NamedTuples such as :class:`.hierarchical.AtNext` and
:class:`.initiation.Stores`, and the agent's :class:`~skillchain_torch.agents.step_state.
StepState`), never an object's attributes. ``native_maths.h`` holds the arithmetic the kernels
share (dot products, epsilon-greedy, the sweeps' exponential, SplitMix64).

Example:
    >>> from skillchain_torch.backends import compiled
    >>> compiled(None, {"built": True, "the CPU": False})   # the torch path, silently
    False
"""

from skillchain_torch.backends.select import builtin_type_problems, compiled, same_bits_kernels

__all__ = ["builtin_type_problems", "compiled", "same_bits_kernels"]
