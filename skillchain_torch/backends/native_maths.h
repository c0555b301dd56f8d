/* Arithmetic shared by the compiled kernels (skillchain_torch/backends/_sarsa.c,
 * skillchain_torch/backends/_hierarchical.c, skillchain_torch/backends/_initiation.c,
 * skillchain_torch/backends/_rng.c).
 *
 * dot: eight interleaved partial sums in a fixed order, so a value depends only on its two
 * vectors (not on the batch, the alignment or the other agents). It differs from torch's
 * (a * b).sum(-1) in the last bits: torch's summation order is its own.
 *
 * epsilon_greedy: skillchain_torch.policies.epsilon_greedy's rule for one agent, decision for
 * decision: u0 < epsilon explores among the available decisions, otherwise the available
 * maximisers of q are the candidates; u1 picks the floor(u1 * count)-th of them.
 *
 * exp_lane: the logistic sweeps' exponential (within 1 ulp of libm's; its own bits).
 *
 * splitmix64: the random streams' and the reservoir's hash (rng.py's, bit for bit).
 *
 * Compiled with -ffp-contract=off: no fused multiply-adds.
 */
#ifndef SKILLCHAIN_NATIVE_MATHS_H
#define SKILLCHAIN_NATIVE_MATHS_H

#include <math.h>
#include <stdint.h>
#include <string.h>

/* NATIVE_CLONES on a kernel's entry point: GCC builds it twice, for AVX2 and for any x86-64,
 * and picks one when the module loads. The helpers it inlines come along, so the dot products
 * run four lanes wide where the CPU has them. The bits stay the same: each of dot's eight
 * partial sums keeps its own order in any lane, and no multiply-add is fused (AVX2 alone
 * brings no FMA, and -ffp-contract=off). -DSKILLCHAIN_NO_CLONES builds the plain x86-64 code only
 * (tests/backends/test_native_clones.py compares them). */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) \
    && !defined(SKILLCHAIN_NO_CLONES)
#define NATIVE_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define NATIVE_CLONES
#endif

/* PREFETCH: ask the memory for the cache line holding an address early (no effect on any
 * result; nothing where the compiler has no such builtin). */
#if defined(__GNUC__)
#define PREFETCH(address) __builtin_prefetch(address)
#else
#define PREFETCH(address) ((void)0)
#endif

static inline double dot(const double *a, const double *b, long n)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0, s5 = 0.0, s6 = 0.0, s7 = 0.0;
    long f = 0;
    for (; f + 8 <= n; f += 8) {
        s0 += a[f] * b[f];
        s1 += a[f + 1] * b[f + 1];
        s2 += a[f + 2] * b[f + 2];
        s3 += a[f + 3] * b[f + 3];
        s4 += a[f + 4] * b[f + 4];
        s5 += a[f + 5] * b[f + 5];
        s6 += a[f + 6] * b[f + 6];
        s7 += a[f + 7] * b[f + 7];
    }
    double tail = 0.0;
    for (; f < n; f++) tail += a[f] * b[f];
    return (((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))) + tail;
}

/* exp(x) within 1 ulp of libm's, in operations a compiler can run four lanes wide (libm's
 * exp is a call per value: it was ~60% of a logistic sweep). Cody-Waite reduction
 * x = k ln2 + r (|r| <= ln2 / 2, k from the round-to-nearest trick of adding 1.5 * 2^52), a
 * degree-13 Taylor polynomial for exp(r) by Horner's rule, then 2^k in two halves so that
 * results near overflow and subnormal ones scale without an intermediate overflow. Only
 * IEEE additions, multiplications and integer shifts: every lane and the scalar code give the
 * same bits. exp(NaN) = NaN, exp(x > 709.8) = inf, exp(x < -745.2) = 0, as libm. */
static inline double exp_lane(double x)
{
    const double shifter = 0x1.8p52, log2e = 0x1.71547652b82fep0;
    const double ln2_hi = 0x1.62e42fefa3800p-1, ln2_lo = 0x1.ef35793c76730p-45;
    double xc = x > 709.8 ? 709.8 : (x < -745.2 ? -745.2 : x);
    double t = xc * log2e + shifter; /* k in the low bits of t */
    double k = t - shifter;
    double r = (xc - k * ln2_hi) - k * ln2_lo; /* k * ln2_hi is exact */
    double p = 1.0 / 6227020800.0;
    p = p * r + 1.0 / 479001600.0;
    p = p * r + 1.0 / 39916800.0;
    p = p * r + 1.0 / 3628800.0;
    p = p * r + 1.0 / 362880.0;
    p = p * r + 1.0 / 40320.0;
    p = p * r + 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    int64_t t_bits, k_int, half, b1, b2;
    memcpy(&t_bits, &t, sizeof t_bits);
    k_int = t_bits - 0x18000000000000LL;
    half = k_int >> 1;
    b1 = (half + 1023) << 52;
    b2 = (k_int - half + 1023) << 52;
    double s1, s2;
    memcpy(&s1, &b1, sizeof s1);
    memcpy(&s2, &b2, sizeof s2);
    double y = (p * s1) * s2;
    y = x > 709.8 ? INFINITY : y;
    y = x < -745.2 ? 0.0 : y;
    return x != x ? x : y;
}

#define GOLDEN_GAMMA 0x9E3779B97F4A7C15ULL

/* SplitMix64's output function, as skillchain_torch.rng.splitmix64 (uint64 arithmetic wraps
 * as torch's int64 does): CounterRNG's draws and the example stores' reservoir hash. */
static inline uint64_t splitmix64(uint64_t x)
{
    uint64_t z = x + GOLDEN_GAMMA;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* Largest of q[d] over the d with ok[d] (all when ok is 0); NaN if any of them is NaN (as
 * torch's amax), -inf if none. */
static inline double masked_max(const double *q, const uint8_t *ok, long n)
{
    double m = -INFINITY;
    for (long d = 0; d < n; d++) {
        if (ok && !ok[d]) continue;
        if (isnan(q[d])) return NAN;
        if (q[d] > m) m = q[d];
    }
    return m;
}

/* One agent's epsilon-greedy decision among n (ok: availability, 0 = all available). */
static inline long epsilon_greedy(const double *q, const uint8_t *ok, long n, double epsilon,
                           double u0, double u1)
{
    int explore = u0 < epsilon;
    double m = explore ? 0.0 : masked_max(q, ok, n);
    long count = 0;
    for (long d = 0; d < n; d++)
        if ((!ok || ok[d]) && (explore || q[d] == m)) count++;
    if (count == 0) return 0;  /* NaN among the values: torch's argmax of nothing */
    long k = (long)floor(u1 * (double)count);
    if (k > count - 1) k = count - 1;
    for (long d = 0; d < n; d++)
        if ((!ok || ok[d]) && (explore || q[d] == m) && k-- == 0) return d;
    return 0;
}

#endif
