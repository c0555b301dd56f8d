"""Build hook for the compiled pieces; everything else is in ``pyproject.toml``.

* ``envs/pinball/_native.c``: the Pinball step (same bits as the Python-float physics);
* ``skillchain_torch/features/_fourier_native.c``: FourierBasis's arguments (same bits);
* ``skillchain_torch/backends/_sarsa.c``: the flat Sarsa agent's per-step arithmetic;
* ``skillchain_torch/_rng_native.c``: CounterRNG's draws (same bits);
* ``skillchain_torch/discovery/_discovery_native.c``: skill chaining's bookkeeping (same bits);
* ``skillchain_torch/options/_initiation_native.c``: initiation-set memberships and fits;
* ``skillchain_torch/agents/_hierarchical_native.c``: the hierarchical agent's per-step
  arithmetic (top-level choice and SMDP update, option actions, intra-option updates).

The agent kernels and the random draws share ``skillchain_torch/native_maths.h`` (dot products,
epsilon-greedy, the sweeps' exponential, SplitMix64).

All are optional: without a C compiler the install still succeeds and the code falls back to
its torch and Python paths, only slower (each module's ``AVAILABLE``, e.g.
``skillchain_torch.envs.pinball.native.AVAILABLE``; ``skillchain_torch.features.fourier.NATIVE``).
``-ffp-contract=off`` keeps the compiler from fusing multiply-adds, which would change the last
bits of trajectories; ``-fno-trapping-math`` (floating-point exceptions are never inspected) lets
it turn comparisons into selects so that loops run several lanes wide, with the same values.
The agent kernels' entry points are built twice on x86-64 Linux with GCC (``NATIVE_CLONES`` in
``native_maths.h``: AVX2 and plain x86-64, picked when the module loads; the same bits).
"""

from setuptools import Extension, setup

FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fno-trapping-math"]
SHARED = dict(include_dirs=["skillchain_torch"], depends=["skillchain_torch/native_maths.h"],
              extra_compile_args=FLAGS, optional=True)

setup(
    ext_modules=[
        Extension("skillchain_torch.envs.pinball._native", sources=["envs/pinball/_native.c"],
                  extra_compile_args=FLAGS, optional=True),
        Extension("skillchain_torch.features._fourier_native",
                  sources=["skillchain_torch/features/_fourier_native.c"], extra_compile_args=FLAGS,
                  optional=True),
        Extension("skillchain_torch._rng_native", sources=["skillchain_torch/_rng_native.c"],
                  **SHARED),
        Extension("skillchain_torch.discovery._discovery_native",
                  sources=["skillchain_torch/discovery/_discovery_native.c"],
                  extra_compile_args=FLAGS, optional=True),
        Extension("skillchain_torch.backends._sarsa",
                  sources=["skillchain_torch/backends/_sarsa.c"], **SHARED),
        Extension("skillchain_torch.options._initiation_native",
                  sources=["skillchain_torch/options/_initiation_native.c"], **SHARED),
        Extension("skillchain_torch.agents._hierarchical_native",
                  sources=["skillchain_torch/agents/_hierarchical_native.c"], **SHARED),
    ]
)
