"""Build hook for the compiled pieces; everything else is in ``pyproject.toml``.

* ``envs/pinball/_native.c``: the Pinball step (the env's fast path; the same bits as its torch
  physics);
* ``skillchain_torch/backends/``: the kernels that accelerate the library's torch path, each
  beside its glue (``_sarsa.c``: the flat Sarsa agent's per-step arithmetic; ``_fourier.c``:
  FourierBasis's arguments, same bits; ``_rng.c``: CounterRNG's draws, same bits;
  ``_discovery.c``: skill chaining's bookkeeping, same bits; ``_initiation.c``: initiation-set
  memberships and fits; ``_stores.c``: their example stores, same bits; ``_hierarchical.c``:
  the hierarchical agent's per-step arithmetic: top-level choice and SMDP update, option
  actions, intra-option updates).

The agent kernels and the random draws share ``skillchain_torch/backends/native_maths.h`` (dot
products, epsilon-greedy, the sweeps' exponential, SplitMix64).

All are optional: without a C compiler the install still succeeds and the code falls back to
its torch and Python paths, only slower (each module's ``AVAILABLE``, e.g.
``skillchain_torch.envs.pinball.native.AVAILABLE``,
``skillchain_torch.backends.fourier.AVAILABLE``).
``-ffp-contract=off`` keeps the compiler from fusing multiply-adds, which would change the last
bits of trajectories; ``-fno-trapping-math`` (floating-point exceptions are never inspected) lets
it turn comparisons into selects so that loops run several lanes wide, with the same values.
The agent kernels' entry points are built twice on x86-64 Linux with GCC (``NATIVE_CLONES`` in
``native_maths.h``: AVX2 and plain x86-64, picked when the module loads; the same bits).
"""

from setuptools import Extension, setup

FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fno-trapping-math"]
SHARED = dict(include_dirs=["skillchain_torch/backends"],
              depends=["skillchain_torch/backends/native_maths.h"], extra_compile_args=FLAGS,
              optional=True)


def backend(name: str, **options) -> Extension:
    """The kernel ``backends/_<name>.c``, imported as ``skillchain_torch.backends._<name>``."""
    return Extension(f"skillchain_torch.backends._{name}",
                     sources=[f"skillchain_torch/backends/_{name}.c"], **options)


setup(
    ext_modules=[
        Extension("skillchain_torch.envs.pinball._native", sources=["envs/pinball/_native.c"],
                  extra_compile_args=FLAGS, optional=True),
        backend("fourier", extra_compile_args=FLAGS, optional=True),
        backend("rng", **SHARED),
        backend("discovery", extra_compile_args=FLAGS, optional=True),
        backend("sarsa", **SHARED),
        backend("initiation", **SHARED),
        backend("stores", **SHARED),
        backend("hierarchical", **SHARED),
    ]
)
