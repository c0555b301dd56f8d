"""The flat Sarsa step as a numba kernel beside the compiled C kernel, in one invocation.

    pip install numba                       # not a dependency of the project
    python benchmarks/numba_vs_c.py         # P = 1, 10, 100 rows, order-4 Fourier features
    python benchmarks/numba_vs_c.py --calls 20000

The step is ``skillchain_torch.backends.sarsa.sarsa_observe`` (``_sarsa.c``): for each agent
row, Q(s', .) by native_maths.h's dot product (eight interleaved partial sums), the
epsilon-greedy rule from the row's two uniforms, and the Sarsa update of (s, a). Below it is
written again in numba with the same operations in the same order, and both run on the same
CPU float64 arrays (numba reads the tensors' memory through ``Tensor.numpy()``, no copies).
Each row of the table times one kernel call over P rows (best of 5 repeats of ``--calls``
calls, the weights updated in place as in training; the C call includes its Python glue,
``backends/sarsa.py``, as the agent pays it), checks that the two leave the same weights and
choose the same actions bit for bit, and gives the ratio numba / C of the times.

This is a measurement, not a backend: the project does not depend on numba and does not ship
this kernel (a numba backend would have to give the same bits at the same speed to be worth a
second copy of the step).
"""

from __future__ import annotations

import argparse
import functools
import time

import numpy as np
import torch

from skillchain_torch.backends import sarsa as c_sarsa
from skillchain_torch.features import FourierBasis

try:
    import numba
except ModuleNotFoundError:  # the benchmark says so and stops
    numba = None

D, ORDER, EPSILON, ALPHA = 5, 4, 0.01, 0.001


def numba_kernels():
    """The numba step, compiled on first use (the same arithmetic as ``_sarsa.c``)."""
    jit = numba.njit(cache=False, fastmath=False, error_model="numpy")

    @jit
    def dot(a, b):
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        n = a.shape[0]
        f = 0
        while f + 8 <= n:
            s0 += a[f] * b[f]
            s1 += a[f + 1] * b[f + 1]
            s2 += a[f + 2] * b[f + 2]
            s3 += a[f + 3] * b[f + 3]
            s4 += a[f + 4] * b[f + 4]
            s5 += a[f + 5] * b[f + 5]
            s6 += a[f + 6] * b[f + 6]
            s7 += a[f + 7] * b[f + 7]
            f += 8
        tail = 0.0
        while f < n:
            tail += a[f] * b[f]
            f += 1
        return (((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))) + tail

    @jit
    def epsilon_greedy(q, epsilon, u0, u1):
        n = q.shape[0]
        explore = u0 < epsilon
        m = 0.0
        if not explore:
            m = -np.inf
            for d in range(n):
                if np.isnan(q[d]):
                    m = np.nan
                    break
                if q[d] > m:
                    m = q[d]
        count = 0
        for d in range(n):
            if explore or q[d] == m:
                count += 1
        if count == 0:
            return 0
        k = int(np.floor(u1 * count))
        if k > count - 1:
            k = count - 1
        for d in range(n):
            if explore or q[d] == m:
                if k == 0:
                    return d
                k -= 1
        return 0

    @jit
    def sarsa_observe(w, phi, phi_next, action, reward, uniforms, slot, epsilon, step, gamma,
                      use_gamma, next_action):  # fmt: skip
        n, d_count, f_count = w.shape
        q = np.empty(d_count)
        for i in range(n):
            for d in range(d_count):
                q[d] = dot(w[i, d], phi_next[i])
            a1 = epsilon_greedy(q, epsilon, uniforms[i, slot, 0], uniforms[i, slot, 1])
            wa = w[i, action[i]]
            q_sa = dot(wa, phi[i])
            boot = gamma * q[a1] if use_gamma else q[a1]
            delta = (reward[i] + boot) - q_sa
            for f in range(f_count):
                wa[f] += step * (delta * phi[i, f])
            next_action[i] = a1

    return sarsa_observe


def problem(population: int, seed: int = 0):
    """Weights, features, actions, rewards and uniforms of ``population`` agent rows."""
    gen = torch.Generator().manual_seed(seed)
    basis = FourierBasis(4, ORDER)
    w = torch.randn(population, D, basis.num_features, dtype=torch.float64, generator=gen) * 0.1
    phi = basis(torch.rand(population, 4, dtype=torch.float64, generator=gen))
    phi_next = basis(torch.rand(population, 4, dtype=torch.float64, generator=gen))
    action = torch.randint(0, D, (population,), generator=gen)
    reward = torch.full((population,), -5.0, dtype=torch.float64)
    uniforms = torch.rand(population, 64, 2, dtype=torch.float64, generator=gen)
    return w, phi, phi_next, action, reward, uniforms


def time_calls(call, calls: int, repeats: int = 5) -> float:
    """Best time of one call, in microseconds, over ``repeats`` runs of ``calls`` calls."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        best = min(best, (time.perf_counter() - start) / calls)
    return best * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=5_000, help="kernel calls per repeat")
    args = parser.parse_args()
    if numba is None:
        print("numba is not installed (pip install numba): nothing to compare")
        return
    if not c_sarsa.AVAILABLE:
        print("the compiled kernel is not built (no C compiler at install time): nothing to "
              "compare")
        return
    step = torch.tensor(ALPHA, dtype=torch.float64)
    nb_step = numba_kernels()
    print(f"flat Sarsa step (Q, epsilon-greedy, update), D = {D}, order-{ORDER} Fourier "
          f"features; numba {numba.__version__}, numpy {np.__version__}, torch "
          f"{torch.__version__}; best of 5 x {args.calls:,} calls")
    print(f"{'P':>5} | {'C (us/call)':>11} | {'numba (us/call)':>15} | {'numba / C':>9} | "
          f"{'same bits':>9}")
    print(f"{'-' * 5}-|-{'-' * 11}-|-{'-' * 15}-|-{'-' * 9}-|-{'-' * 9}")
    for population in (1, 10, 100):
        w, phi, phi_next, action, reward, uniforms = problem(population)
        # Same bits: one call each from the same start, then many calls each.
        w_c, w_nb = w.clone(), w.clone()
        a_c = c_sarsa.sarsa_observe(w_c, phi, phi_next, action, reward, uniforms, 3, EPSILON,
                                    step, None)  # fmt: skip
        a_nb = np.empty(population, dtype=np.int64)
        args_nb = (phi.numpy(), phi_next.numpy(), action.numpy(), reward.numpy(),
                   uniforms.numpy(), 3, EPSILON, ALPHA, 1.0, False, a_nb)  # fmt: skip
        nb_step(w_nb.numpy(), *args_nb)  # compiles on the first call
        same = torch.equal(w_c, w_nb) and np.array_equal(a_c.numpy(), a_nb)
        for _ in range(200):  # training-like drift of the weights, then compare again
            c_sarsa.sarsa_observe(w_c, phi, phi_next, action, reward, uniforms, 3, EPSILON,
                                  step, None)  # fmt: skip
            nb_step(w_nb.numpy(), *args_nb)
        same = same and torch.equal(w_c, w_nb)
        c_us = time_calls(functools.partial(c_sarsa.sarsa_observe, w_c, phi, phi_next, action,
                                            reward, uniforms, 3, EPSILON, step, None),
                          args.calls)  # fmt: skip
        nb_us = time_calls(functools.partial(nb_step, w_nb.numpy(), *args_nb), args.calls)
        print(f"{population:>5} | {c_us:>11.2f} | {nb_us:>15.2f} | {nb_us / c_us:>9.2f} | "
              f"{'yes' if same else 'NO':>9}")


if __name__ == "__main__":
    main()
