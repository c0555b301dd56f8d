/* The initiation classifier's costly pieces, compiled (see initiation.py).
 *
 * Why it exists: a skill-chaining step asks every slot of every agent whether it holds the new
 * state (a 15-feature logit, then for learned options a distance test against up to C stored
 * positives), and each finished execution stores its examples and refits its slot with 100
 * gradient sweeps. In torch the first is a dozen small operations and a [P, K, C] distance
 * matrix per step, the last five operations per sweep (500 per fit) plus the sorts and hashes
 * of the stores; at P = 100 they took ~3 ms of a ~11 ms step. Here each slot is one pass, the
 * distance test stops at the first positive within reach, and a fit or a batch of examples is
 * one call.
 *
 * Arithmetic: native_maths.h's dot (its own fixed order: not torch's bits, the same for a
 * slot whatever the batch); the sweep keeps logistic_sweeps's expressions
 * (g = -step y + step / (1 + exp(x . v)), v += sum_l x_l g_l, summed over the examples in
 * order) with native_maths.h's exp_lane (within 1 ulp of libm's exp), four examples or
 * features at a time where the compiler has vector types, lane for lane the plain loops'
 * operations; distances are compared squared (a membership can differ from torch's cdist only
 * for a state within rounding of the radius). The stores (store, store_executions) copy and
 * hash integers (their own module, _stores.c): the torch path's bits. Compiled with
 * -ffp-contract=off.
 *
 * Every array argument is an address (torch.Tensor.data_ptr()) of a contiguous CPU tensor;
 * flags are uint8 (torch.bool).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "native_maths.h"

#define OBS_DIM 4

#if defined(__GNUC__)
typedef double lanes4 __attribute__((vector_size(32)));
typedef long long mask4 __attribute__((vector_size(32)));
#define LOAD4(dst, src) memcpy(&(dst), (src), sizeof(lanes4))
#define STORE4(dst, src) memcpy((dst), &(src), sizeof(lanes4))
#endif

/* Examples a distance scan asks the memory for ahead of the one it tests (32 bytes each). */
#define PREFETCH_AHEAD 16
/* Slots whose distance tests contains starts fetching ahead of the one it runs. */
#define SLOTS_AHEAD 4

/* Within `distance` of one of the first `count` stored examples labelled positive, in the
 * dims flagged (squared distances against distance^2: no square root per example). Four
 * examples at a time where the compiler has vector types: each lane computes an example's
 * distance with the scalar loop's operations, so the answer is the same. */
NATIVE_CLONES static int near_positive(const double *point, const double *examples,
                                       const uint8_t *labels, long count, const uint8_t *dims,
                                       double distance)
{
    double m0 = dims[0], m1 = dims[1], m2 = dims[2], m3 = dims[3];
    double p0 = point[0], p1 = point[1], p2 = point[2], p3 = point[3];
    double reach = distance * distance;
    long c = 0;
#if defined(__GNUC__)
    for (; c + 4 <= count; c += 4) {
        const double *e = examples + c * OBS_DIM;
        /* the two cache lines PREFETCH_AHEAD examples on (a scan is too short for the
         * hardware to notice a stream before it ends) */
        PREFETCH(e + PREFETCH_AHEAD * OBS_DIM);
        PREFETCH(e + PREFETCH_AHEAD * OBS_DIM + 8);
        lanes4 x0 = {e[0], e[4], e[8], e[12]}, x1 = {e[1], e[5], e[9], e[13]};
        lanes4 x2 = {e[2], e[6], e[10], e[14]}, x3 = {e[3], e[7], e[11], e[15]};
        lanes4 d0 = (p0 - x0) * m0, d1 = (p1 - x1) * m1, d2 = (p2 - x2) * m2;
        lanes4 d3 = (p3 - x3) * m3;
        mask4 positive = {labels[c], labels[c + 1], labels[c + 2], labels[c + 3]};
        mask4 hit = ((((d0 * d0 + d1 * d1) + d2 * d2) + d3 * d3) <= reach) & (positive != 0);
        if (hit[0] | hit[1] | hit[2] | hit[3]) return 1;
    }
#endif
    for (; c < count; c++) {
        if (!labels[c]) continue;
        const double *e = examples + c * OBS_DIM;
        double d0 = (p0 - e[0]) * m0, d1 = (p1 - e[1]) * m1;
        double d2 = (p2 - e[2]) * m2, d3 = (p3 - e[3]) * m3;
        if (((d0 * d0 + d1 * d1) + d2 * d2) + d3 * d3 <= reach) return 1;
    }
    return 0;
}

/* constrain_nearest's test: within `distance` of a stored positive, and no stored negative
 * strictly nearer than the nearest positive (squared distances as near_positive's; every
 * stored example is read, so it runs only where the classifier asks for it). */
static int nearest_is_positive(const double *point, const double *examples,
                               const uint8_t *labels, long count, const uint8_t *dims,
                               double distance)
{
    double m0 = dims[0], m1 = dims[1], m2 = dims[2], m3 = dims[3];
    double positive = INFINITY, negative = INFINITY;
    for (long c = 0; c < count; c++) {
        const double *e = examples + c * OBS_DIM;
        double d0 = (point[0] - e[0]) * m0, d1 = (point[1] - e[1]) * m1;
        double d2 = (point[2] - e[2]) * m2, d3 = (point[3] - e[3]) * m3;
        double squared = ((d0 * d0 + d1 * d1) + d2 * d2) + d3 * d3;
        if (labels[c]) {
            if (squared < positive) positive = squared;
        } else if (squared < negative) {
            negative = squared;
        }
    }
    return positive <= distance * distance && !(negative < positive);
}

/* The first PREFETCH_AHEAD examples of a slot's store and its first labels, asked for early. */
static inline void fetch_first_examples(const double *examples, const uint8_t *labels)
{
    for (int line = 0; line < PREFETCH_AHEAD * OBS_DIM; line += 8) PREFETCH(examples + line);
    PREFETCH(labels);
}

#define MAX_FEATURES 256

/* The classifier's features of one observation, as PolynomialFeatures computes them: each a
 * product of factors of [1, x_1, ..., x_4] taken left to right (factor_index [F, degree]),
 * of 2 x - 1 when centred; the same operations in the same order, so the same bits. */
static void polynomial_row(const double *obs, const int64_t *factor_index, Py_ssize_t F,
                           Py_ssize_t degree, int centered, double *phi)
{
    double padded[OBS_DIM + 1];
    padded[0] = 1.0;
    for (int j = 0; j < OBS_DIM; j++) padded[j + 1] = centered ? 2.0 * obs[j] - 1.0 : obs[j];
    for (Py_ssize_t f = 0; f < F; f++) {
        const int64_t *factors = factor_index + f * degree;
        double value = padded[factors[0]];
        for (Py_ssize_t j = 1; j < degree; j++) value = value * padded[factors[j]];
        phi[f] = value;
    }
}

/* contains(P, K, F, C, factor_index, degree, centered, weight, bias, trained, constrained,
 * obs, examples, labels, count, dims, distance, out, nearest): out[p, k] = (logit > 0 or
 * untrained), and for constrained slots also near a stored positive (and with nearest, no
 * stored negative nearer than the nearest positive). factor_index [F, degree] (int64),
 * weight [P, K, F], bias [P, K], obs [P, 4], examples [P, K, C, 4], labels [P, K, C],
 * count [P, K] (int64), dims uint8 [4]. */
NATIVE_CLONES static PyObject *contains(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, F, C, degree;
    unsigned long long fi_p, w_p, b_p, tr_p, co_p, obs_p, ex_p, lab_p, cnt_p, dims_p, out_p;
    double distance;
    int centered, nearest = 0;
    if (!PyArg_ParseTuple(args, "nnnnKniKKKKKKKKKdK|i", &P, &K, &F, &C, &fi_p, &degree,
                          &centered, &w_p, &b_p, &tr_p, &co_p, &obs_p, &ex_p, &lab_p, &cnt_p,
                          &dims_p, &distance, &out_p, &nearest))
        return NULL;
    if (F > MAX_FEATURES) {
        PyErr_SetString(PyExc_ValueError, "contains: at most 256 classifier features");
        return NULL;
    }
    const int64_t *factor_index = (const int64_t *)(uintptr_t)fi_p;
    double phi[MAX_FEATURES];
    const double *w = (const double *)(uintptr_t)w_p;
    const double *bias = (const double *)(uintptr_t)b_p, *obs = (const double *)(uintptr_t)obs_p;
    const double *examples = (const double *)(uintptr_t)ex_p;
    const uint8_t *trained = (const uint8_t *)(uintptr_t)tr_p;
    const uint8_t *constrained = (const uint8_t *)(uintptr_t)co_p;
    const uint8_t *labels = (const uint8_t *)(uintptr_t)lab_p;
    const uint8_t *dims = (const uint8_t *)(uintptr_t)dims_p;
    const int64_t *count = (const int64_t *)(uintptr_t)cnt_p;
    uint8_t *out = (uint8_t *)(uintptr_t)out_p;
    /* Pass 1: the logits; the slots that still need the distance test are listed. Pass 2:
     * those tests, each slot's first examples and labels fetched SLOTS_AHEAD tests early. The
     * stores (P K C examples) are far larger than the caches, and a test that hits reads a
     * few dozen examples: waiting on memory for each slot in turn was most of its cost. */
    Py_ssize_t *pending = (Py_ssize_t *)malloc(sizeof(Py_ssize_t) * (size_t)(P * K + 1));
    if (!pending) return PyErr_NoMemory();
    Py_ssize_t n = 0;
    for (Py_ssize_t p = 0; p < P; p++) {
        polynomial_row(obs + p * OBS_DIM, factor_index, F, degree, centered, phi);
        for (Py_ssize_t k = 0; k < K; k++) {
            Py_ssize_t s = p * K + k;
            int member = !trained[s] || dot(w + s * F, phi, F) + bias[s] > 0.0;
            if (member && constrained[s]) pending[n++] = s;
            out[s] = (uint8_t)member;
        }
    }
    for (Py_ssize_t i = 0; i < n && i < SLOTS_AHEAD; i++)
        fetch_first_examples(examples + pending[i] * C * OBS_DIM, labels + pending[i] * C);
    for (Py_ssize_t i = 0; i < n; i++) {
        if (i + SLOTS_AHEAD < n) {
            Py_ssize_t t = pending[i + SLOTS_AHEAD];
            fetch_first_examples(examples + t * C * OBS_DIM, labels + t * C);
        }
        Py_ssize_t s = pending[i], p = s / K;
        out[s] = (uint8_t)(nearest ? nearest_is_positive : near_positive)(
            obs + p * OBS_DIM, examples + s * C * OBS_DIM, labels + s * C, (long)count[s], dims,
            distance);
    }
    free(pending);
    Py_RETURN_NONE;
}

/* The two sums of a sweep over L examples of F1 features, written so that a compiler runs
 * them four lanes wide, each lane doing what the plain loop at the end does (so the same bits):
 * z_l = dot(x_l, v) for every l, from the examples transposed (xt [F1, L]: four examples'
 * feature f side by side), and dv_f = sum_l x_l[f] g_l in the order of l (x [L, F1]: the
 * four features of a lane side by side). */
NATIVE_CLONES static void example_dots(const double *xt, const double *v, Py_ssize_t L,
                                      Py_ssize_t F1, double *z)
{
    Py_ssize_t l = 0;
#if defined(__GNUC__)
    for (; l + 4 <= L; l += 4) { /* native_maths.h's dot, four examples at a time */
        lanes4 s[8] = {{0.0}}, tail = {0.0}, column;
        Py_ssize_t f = 0;
        for (; f + 8 <= F1; f += 8)
            for (int j = 0; j < 8; j++) {
                LOAD4(column, xt + (f + j) * L + l);
                s[j] += column * v[f + j];
            }
        for (; f < F1; f++) {
            LOAD4(column, xt + f * L + l);
            tail += column * v[f];
        }
        lanes4 r = (((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]))) + tail;
        STORE4(z + l, r);
    }
#endif
    for (; l < L; l++) { /* one at a time: the last few, or all without vector types */
        double s[8] = {0.0}, tail = 0.0;
        Py_ssize_t f = 0;
        for (; f + 8 <= F1; f += 8)
            for (int j = 0; j < 8; j++) s[j] += xt[(f + j) * L + l] * v[f + j];
        for (; f < F1; f++) tail += xt[f * L + l] * v[f];
        z[l] = (((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]))) + tail;
    }
}

NATIVE_CLONES static void feature_sums(const double *x, const double *g, Py_ssize_t L,
                                      Py_ssize_t F1, double *dv)
{
    Py_ssize_t f = 0;
#if defined(__GNUC__)
    for (; f + 16 <= F1; f += 16) { /* four independent chains of additions */
        lanes4 a0 = {0.0}, a1 = {0.0}, a2 = {0.0}, a3 = {0.0}, r0, r1, r2, r3;
        for (Py_ssize_t l = 0; l < L; l++) {
            const double *row = x + l * F1 + f;
            LOAD4(r0, row);
            LOAD4(r1, row + 4);
            LOAD4(r2, row + 8);
            LOAD4(r3, row + 12);
            a0 += r0 * g[l];
            a1 += r1 * g[l];
            a2 += r2 * g[l];
            a3 += r3 * g[l];
        }
        STORE4(dv + f, a0);
        STORE4(dv + f + 4, a1);
        STORE4(dv + f + 8, a2);
        STORE4(dv + f + 12, a3);
    }
    for (; f + 4 <= F1; f += 4) {
        lanes4 a = {0.0}, r;
        for (Py_ssize_t l = 0; l < L; l++) {
            LOAD4(r, x + l * F1 + f);
            a += r * g[l];
        }
        STORE4(dv + f, a);
    }
#endif
    for (; f < F1; f++) { /* one feature at a time */
        double a = 0.0;
        for (Py_ssize_t l = 0; l < L; l++) a += x[l * F1 + f] * g[l];
        dv[f] = a;
    }
}

/* Doubles of scratch sweep_slot needs. */
static size_t sweep_work(Py_ssize_t L, Py_ssize_t F1) { return (size_t)(L * F1 + 2 * L + F1 + 1); }

/* n_sweeps gradient steps of one slot over its first L examples (x [L, F1], the last feature
 * the constant 1; v [F1], the negated parameters, in place): z_l = x_l . v,
 * g_l = minus_step_y_l + step_l / (exp(z_l) + 1) (0 for empty places, step 0), then
 * v += sum_l x_l g_l, summed in the order of l. work: sweep_work(L, F1) doubles. */
NATIVE_CLONES static void sweep_slot(const double *x, const double *step, const double *msy,
                                     double *v, Py_ssize_t L, Py_ssize_t F1, Py_ssize_t n_sweeps,
                                     double *work)
{
    double *xt = work, *z = xt + L * F1, *g = z + L, *dv = g + L;
    for (Py_ssize_t l = 0; l < L; l++)
        for (Py_ssize_t f = 0; f < F1; f++) xt[f * L + l] = x[l * F1 + f];
    for (Py_ssize_t it = 0; it < n_sweeps; it++) {
        example_dots(xt, v, L, F1, z);
        for (Py_ssize_t l = 0; l < L; l++)
            g[l] = step[l] == 0.0 ? 0.0 : msy[l] + step[l] / (exp_lane(z[l]) + 1.0);
        feature_sums(x, g, L, F1, dv);
        for (Py_ssize_t f = 0; f < F1; f++) v[f] += dv[f];
    }
}

/* sweeps(M, L, F1, x, step, minus_step_y, v, n_sweeps): sweep_slot for each of M slots.
 * x [M, L, F1], step and minus_step_y [M, L], v [M, F1] in place. */
static PyObject *sweeps(PyObject *self, PyObject *args)
{
    Py_ssize_t M, L, F1, n_sweeps;
    unsigned long long x_p, step_p, msy_p, v_p;
    if (!PyArg_ParseTuple(args, "nnnKKKKn", &M, &L, &F1, &x_p, &step_p, &msy_p, &v_p,
                          &n_sweeps))
        return NULL;
    const double *x = (const double *)(uintptr_t)x_p, *step = (const double *)(uintptr_t)step_p;
    const double *msy = (const double *)(uintptr_t)msy_p;
    double *v = (double *)(uintptr_t)v_p;
    double *work = (double *)malloc(sizeof(double) * sweep_work(L, F1));
    if (!work) return PyErr_NoMemory();
    for (Py_ssize_t m = 0; m < M; m++)
        sweep_slot(x + m * L * F1, step + m * L, msy + m * L, v + m * F1, L, F1, n_sweeps,
                   work);
    free(work);
    Py_RETURN_NONE;
}

/* fit(P, K, C, F, factor_index, degree, centered, mask, examples, labels, count, weight, bias,
 * lr, n_sweeps, balanced, sweeps_done, trained, dirty, fitted): InitiationClassifier.fit for
 * every slot in mask (uint8 [P, K]) that stores an example, in place on weight [P, K, F] and
 * bias [P, K]; those slots get sweeps_done += n_sweeps, trained = 1, dirty = 0, fitted = 1
 * (fitted = 0 elsewhere). The numbers are those of logistic.sweep_terms and the sweeps above:
 * the polynomial features of the slot's `count` stored examples with a constant 1 appended;
 * each example's step is lr / count, or lr * 0.5 / (its class's count, at least 1) when
 * balanced; minus_step_y is -(step * y); v starts at -(weight, bias) and the result is -v. */
static PyObject *fit(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, C, F, degree, n_sweeps;
    unsigned long long fi_p, mask_p, ex_p, lab_p, cnt_p, w_p, b_p, done_p, tr_p, dirty_p, out_p;
    int centered, balanced;
    double lr;
    if (!PyArg_ParseTuple(args, "nnnnKniKKKKKKdniKKKK", &P, &K, &C, &F, &fi_p, &degree,
                          &centered, &mask_p, &ex_p, &lab_p, &cnt_p, &w_p, &b_p, &lr, &n_sweeps,
                          &balanced, &done_p, &tr_p, &dirty_p, &out_p))
        return NULL;
    int64_t *sweeps_done = (int64_t *)(uintptr_t)done_p;
    uint8_t *trained = (uint8_t *)(uintptr_t)tr_p, *dirty = (uint8_t *)(uintptr_t)dirty_p;
    uint8_t *fitted = (uint8_t *)(uintptr_t)out_p;
    const int64_t *factor_index = (const int64_t *)(uintptr_t)fi_p;
    const uint8_t *mask = (const uint8_t *)(uintptr_t)mask_p;
    const double *examples = (const double *)(uintptr_t)ex_p;
    const uint8_t *labels = (const uint8_t *)(uintptr_t)lab_p;
    const int64_t *count = (const int64_t *)(uintptr_t)cnt_p;
    double *weight = (double *)(uintptr_t)w_p, *bias = (double *)(uintptr_t)b_p;
    Py_ssize_t F1 = F + 1;
    double *x = (double *)malloc(sizeof(double) * (C * F1 + 2 * C + F1 + sweep_work(C, F1)));
    if (!x) return PyErr_NoMemory();
    double *step = x + C * F1, *msy = step + C, *v = msy + C, *work = v + F1;
    for (Py_ssize_t s = 0; s < P * K; s++) {
        Py_ssize_t L = (Py_ssize_t)count[s];
        fitted[s] = mask[s] && L > 0;
        if (!fitted[s]) continue;
        if (L > C) L = C;
        sweeps_done[s] += n_sweeps;
        trained[s] = 1;
        dirty[s] = 0;
        const uint8_t *y = labels + s * C;
        double positives = 0.0;
        for (Py_ssize_t l = 0; l < L; l++) {
            polynomial_row(examples + (s * C + l) * OBS_DIM, factor_index, F, degree, centered,
                           x + l * F1);
            x[l * F1 + F] = 1.0;
            positives += y[l] ? 1.0 : 0.0;
        }
        double negatives = (double)L - positives;
        for (Py_ssize_t l = 0; l < L; l++) {
            double weight_l = balanced ? 0.5 / (y[l] ? fmax(positives, 1.0) : fmax(negatives, 1.0))
                                       : 1.0 / (double)L;
            step[l] = lr * weight_l;
            msy[l] = -(step[l] * (y[l] ? 1.0 : 0.0));
        }
        double *w = weight + s * F;
        for (Py_ssize_t f = 0; f < F; f++) v[f] = -w[f];
        v[F] = -bias[s];
        sweep_slot(x, step, msy, v, L, F1, n_sweeps, work);
        for (Py_ssize_t f = 0; f < F; f++) w[f] = -v[f];
        bias[s] = -v[F];
    }
    free(x);
    Py_RETURN_NONE;
}


/* exp(n, x, out): out[i] = exp_lane(x[i]), the sweeps' exponential (exposed so that its
 * accuracy against libm can be checked). */
NATIVE_CLONES static PyObject *exp_(PyObject *self, PyObject *args)
{
    Py_ssize_t n;
    unsigned long long x_p, out_p;
    if (!PyArg_ParseTuple(args, "nKK", &n, &x_p, &out_p)) return NULL;
    const double *x = (const double *)(uintptr_t)x_p;
    double *out = (double *)(uintptr_t)out_p;
    for (Py_ssize_t i = 0; i < n; i++) out[i] = exp_lane(x[i]);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"contains", contains, METH_VARARGS, "Initiation-set memberships of one state per agent."},
    {"sweeps", sweeps, METH_VARARGS, "Logistic-regression gradient sweeps of some slots."},
    {"exp", exp_, METH_VARARGS, "The sweeps' exponential of an array (exp_lane)."},
    {"fit", fit, METH_VARARGS, "A classifier's fits of the slots in a mask, in place."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_initiation",
                                    "Compiled initiation classifier (see initiation.py).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__initiation(void) { return PyModule_Create(&module); }
