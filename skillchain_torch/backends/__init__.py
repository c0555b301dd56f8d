"""Compiled accelerators of the torch path, and the one rule that chooses them.

A backend is never the definition of a rule: the torch path is. :func:`select.compiled` is the
single switch every piece asks (the classifier, the agents): a kernel runs only where every
piece it replaces is *exactly* the built-in class (not a subclass), on the CPU in float64, and
built; otherwise the torch path runs, and asking for the kernel anyway is a ``ValueError``
naming the piece.

Most kernels still sit beside the modules they serve (``*_native.c`` with their glue,
``native_*.py``); the flat Sarsa step is here (:mod:`.sarsa` over ``_sarsa.c``). They take
declared tensors.
"""

from skillchain_torch.backends.select import builtin_type_problems, compiled

__all__ = ["builtin_type_problems", "compiled"]
