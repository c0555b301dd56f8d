/* The initiation classifier's two costly pieces, compiled (see native_initiation.py).
 *
 * Why it exists: a skill-chaining step asks every slot of every agent whether it holds the new
 * state (a 15-feature logit, then for learned options a distance test against up to C stored
 * positives), and each finished execution refits its slot with 100 gradient sweeps. In torch
 * the first is a dozen small operations and a [P, K, C] distance matrix per step, the second
 * five operations per sweep (500 per fit); at P = 100 they took ~3 ms of a ~11 ms step. Here
 * each slot is one pass, and the distance test stops at the first positive within reach.
 *
 * Arithmetic: native_maths.h's dot (its own fixed order: not torch's bits, the same for a
 * slot whatever the batch); the sweep keeps logistic_sweeps's expressions
 * (g = -step y + step / (1 + exp(x . v)), v += sum_l x_l g_l, summed over the examples in
 * order); distances are compared squared (a membership can differ from torch's cdist only
 * for a state within rounding of the radius). Compiled with -ffp-contract=off.
 *
 * Every array argument is an address (torch.Tensor.data_ptr()) of a contiguous CPU tensor;
 * flags are uint8 (torch.bool).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

#include "native_maths.h"

#define OBS_DIM 4

/* Within `distance` of one of the first `count` stored examples labelled positive, in the
 * dims flagged (squared distances against distance^2: no square root per example). */
static int near_positive(const double *point, const double *examples, const uint8_t *labels,
                         long count, const uint8_t *dims, double distance)
{
    double m0 = dims[0], m1 = dims[1], m2 = dims[2], m3 = dims[3];
    double reach = distance * distance;
    for (long c = 0; c < count; c++) {
        if (!labels[c]) continue;
        const double *e = examples + c * OBS_DIM;
        double d0 = (point[0] - e[0]) * m0, d1 = (point[1] - e[1]) * m1;
        double d2 = (point[2] - e[2]) * m2, d3 = (point[3] - e[3]) * m3;
        if (((d0 * d0 + d1 * d1) + d2 * d2) + d3 * d3 <= reach) return 1;
    }
    return 0;
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
 * obs, examples, labels, count, dims, distance, out): out[p, k] = (logit > 0 or untrained),
 * and for constrained slots also near a stored positive. factor_index [F, degree] (int64),
 * weight [P, K, F], bias [P, K], obs [P, 4], examples [P, K, C, 4], labels [P, K, C],
 * count [P, K] (int64), dims uint8 [4]. */
static PyObject *contains(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, F, C, degree;
    unsigned long long fi_p, w_p, b_p, tr_p, co_p, obs_p, ex_p, lab_p, cnt_p, dims_p, out_p;
    double distance;
    int centered;
    if (!PyArg_ParseTuple(args, "nnnnKniKKKKKKKKKdK", &P, &K, &F, &C, &fi_p, &degree,
                          &centered, &w_p, &b_p, &tr_p, &co_p, &obs_p, &ex_p, &lab_p, &cnt_p,
                          &dims_p, &distance, &out_p))
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
    for (Py_ssize_t p = 0; p < P; p++) {
        polynomial_row(obs + p * OBS_DIM, factor_index, F, degree, centered, phi);
        for (Py_ssize_t k = 0; k < K; k++) {
            Py_ssize_t s = p * K + k;
            int member = !trained[s] || dot(w + s * F, phi, F) + bias[s] > 0.0;
            if (member && constrained[s])
                member = near_positive(obs + p * OBS_DIM, examples + s * C * OBS_DIM,
                                       labels + s * C, (long)count[s], dims, distance);
            out[s] = (uint8_t)member;
        }
    }
    Py_RETURN_NONE;
}

/* sweeps(M, L, F1, x, step, minus_step_y, v, n_sweeps): for each slot m, n_sweeps times:
 * z_l = x_l . v, g_l = minus_step_y_l + step_l / (exp(z_l) + 1), v += sum_l x_l g_l.
 * x [M, L, F1] (last feature the constant 1), step and minus_step_y [M, L], v [M, F1] in
 * place. Places with step 0 (empty) add exactly nothing and are skipped. */
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
    double *dv = (double *)malloc(sizeof(double) * (size_t)(F1 > 0 ? F1 : 1));
    if (!dv) return PyErr_NoMemory();
    for (Py_ssize_t m = 0; m < M; m++) {
        const double *xm = x + m * L * F1, *sm = step + m * L, *ym = msy + m * L;
        double *vm = v + m * F1;
        for (Py_ssize_t it = 0; it < n_sweeps; it++) {
            for (Py_ssize_t f = 0; f < F1; f++) dv[f] = 0.0;
            for (Py_ssize_t l = 0; l < L; l++) {
                if (sm[l] == 0.0) continue;
                const double *xl = xm + l * F1;
                double g = ym[l] + sm[l] / (exp(dot(xl, vm, F1)) + 1.0);
                for (Py_ssize_t f = 0; f < F1; f++) dv[f] += xl[f] * g;
            }
            for (Py_ssize_t f = 0; f < F1; f++) vm[f] += dv[f];
        }
    }
    free(dv);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"contains", contains, METH_VARARGS, "Initiation-set memberships of one state per agent."},
    {"sweeps", sweeps, METH_VARARGS, "Logistic-regression gradient sweeps of some slots."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_initiation_native",
                                    "Compiled initiation classifier (see native_initiation.py).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__initiation_native(void) { return PyModule_Create(&module); }
