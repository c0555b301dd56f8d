"""Build hook for the two compiled pieces; everything else is in ``pyproject.toml``.

* ``envs/pinball/_native.c``: the Pinball step (same bits as the Python-float physics);
* ``skillchain_torch/features/_fourier_native.c``: FourierBasis's arguments (same bits);
* ``trainers/_sarsa_native.c``: the flat Sarsa agent's per-step arithmetic.

All are optional: without a C compiler the install still succeeds and the code falls back to
its torch and Python paths (``skillchain_torch.envs.pinball.native.AVAILABLE``,
``skillchain_torch.features.fourier.NATIVE``, ``skillchain_torch.trainers.native_sarsa.AVAILABLE``),
only slower. ``-ffp-contract=off`` keeps
the compiler from fusing multiply-adds, which would change the last bits of trajectories.
"""

from setuptools import Extension, setup

FLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math"]

setup(
    ext_modules=[
        Extension("skillchain_torch.envs.pinball._native", sources=["envs/pinball/_native.c"],
                  extra_compile_args=FLAGS, optional=True),
        Extension("skillchain_torch.features._fourier_native",
                  sources=["skillchain_torch/features/_fourier_native.c"], extra_compile_args=FLAGS,
                  optional=True),
        Extension("skillchain_torch.trainers._sarsa_native",
                  sources=["trainers/_sarsa_native.c"], extra_compile_args=FLAGS, optional=True),
    ]
)
