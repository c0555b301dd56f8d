/* The hierarchical agent's per-step arithmetic, compiled (see native_hierarchical.py).
 *
 * Why it exists: with options live, a HierarchicalAgent step at P = 100 spent ~4 ms in about
 * sixty small tensor operations: top-level values of the available decisions and the
 * epsilon-greedy choice, the executing options' values and actions, the intra-option updates
 * of every option whose initiation set holds s, and the SMDP update. Here each is one pass
 * over the agents, one agent (and slot) at a time.
 *
 * Arithmetic: native_maths.h's dot and epsilon-greedy rule. The updates keep the expressions
 * of SarsaUpdate (w[d] += step * (delta * phi), delta = (R + gamma^k Q(s', d')) - Q(s, d)) and
 * IntraOptionQLearning / FourierOptionQHead (target = (r + C [T]) + gamma max_a Q(s', a)
 * [no T, not terminated]; w[k, a] += (alpha * delta) * phi). Sums differ from torch's in the
 * last bits; every agent's numbers depend on that agent alone. -ffp-contract=off.
 *
 * Every array argument is an address (torch.Tensor.data_ptr()) of a contiguous CPU tensor
 * unless a stride is given; flags are uint8 (torch.bool), indices int64.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

#include "native_maths.h"

#define MAX_CHOICES 64

#define F64(p) ((double *)(uintptr_t)(p))
#define I64(p) ((int64_t *)(uintptr_t)(p))
#define U8(p) ((uint8_t *)(uintptr_t)(p))

/* choose(P, D, F, w, phi, available, rows, dense, u, u_stride, epsilon, q, decision):
 * for rows: q[p, d] = w[p, d] . phi[p] where available (the first `dense` decisions whenever
 * any of them is), 0 elsewhere and on other rows; then every row's epsilon-greedy decision
 * among its available ones with uniforms u[p * u_stride + 0, 1]. w [P, D, F]. */
static PyObject *choose(PyObject *self, PyObject *args)
{
    Py_ssize_t P, D, F, dense, u_stride;
    unsigned long long w_p, phi_p, av_p, rows_p, u_p, q_p, dec_p;
    double epsilon;
    if (!PyArg_ParseTuple(args, "nnnKKKKnKndKK", &P, &D, &F, &w_p, &phi_p, &av_p, &rows_p,
                          &dense, &u_p, &u_stride, &epsilon, &q_p, &dec_p))
        return NULL;
    if (D > MAX_CHOICES) {
        PyErr_SetString(PyExc_ValueError, "choose: at most 64 decisions");
        return NULL;
    }
    const double *w = F64(w_p), *phi = F64(phi_p), *u = F64(u_p);
    const uint8_t *available = U8(av_p), *rows = U8(rows_p);
    double *q = F64(q_p);
    int64_t *decision = I64(dec_p);
    for (Py_ssize_t p = 0; p < P; p++) {
        const uint8_t *ok = available + p * D;
        double *qp = q + p * D;
        int dense_needed = 0;
        for (Py_ssize_t d = 0; d < dense; d++) dense_needed |= ok[d];
        for (Py_ssize_t d = 0; d < D; d++) {
            int need = rows[p] && (d < dense ? dense_needed : ok[d]);
            qp[d] = need ? dot(w + (p * D + d) * F, phi + p * F, F) : 0.0;
        }
        decision[p] = epsilon_greedy(qp, ok, D, epsilon, u[p * u_stride], u[p * u_stride + 1]);
    }
    Py_RETURN_NONE;
}

/* act(P, K, A, Fo, w, code, rows, decision, option, u, u_stride, epsilon, action): for rows,
 * action[p] = min(decision[p], A - 1), or where option[p] >= 0 that option's epsilon-greedy
 * action by Q_k(s, .) = w[p, k, .] . code[p] with uniforms u[p * u_stride + 0, 1].
 * w [P, K, A, Fo]; other rows keep their action. */
static PyObject *act(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, A, Fo, u_stride;
    unsigned long long w_p, code_p, rows_p, dec_p, opt_p, u_p, act_p;
    double epsilon;
    if (!PyArg_ParseTuple(args, "nnnnKKKKKKndK", &P, &K, &A, &Fo, &w_p, &code_p, &rows_p,
                          &dec_p, &opt_p, &u_p, &u_stride, &epsilon, &act_p))
        return NULL;
    if (A > MAX_CHOICES) {
        PyErr_SetString(PyExc_ValueError, "act: at most 64 actions");
        return NULL;
    }
    const double *w = F64(w_p), *code = F64(code_p), *u = F64(u_p);
    const uint8_t *rows = U8(rows_p);
    const int64_t *decision = I64(dec_p), *option = I64(opt_p);
    int64_t *action = I64(act_p);
    double q[MAX_CHOICES];
    for (Py_ssize_t p = 0; p < P; p++) {
        if (!rows[p]) continue;
        if (option[p] < 0) {
            action[p] = decision[p] < A - 1 ? decision[p] : A - 1;
            continue;
        }
        const double *wk = w + (p * K + option[p]) * A * Fo;
        for (Py_ssize_t a = 0; a < A; a++) q[a] = dot(wk + a * Fo, code + p * Fo, Fo);
        action[p] = epsilon_greedy(q, NULL, A, epsilon, u[p * u_stride], u[p * u_stride + 1]);
    }
    Py_RETURN_NONE;
}

/* smdp(P, D, F, w, phi, decision, ret, duration, q_next, terminal, active, step, step_stride,
 * gamma, use_gamma, delta): for active rows, delta = (R + gamma^k Q(s', d') [not terminal])
 * - w[p, d] . phi[p] and w[p, d] += step * (delta * phi[p]); delta 0 on other rows. */
static PyObject *smdp(PyObject *self, PyObject *args)
{
    Py_ssize_t P, D, F, step_stride;
    unsigned long long w_p, phi_p, dec_p, ret_p, dur_p, qn_p, term_p, act_p, step_p, delta_p;
    double gamma;
    int use_gamma;
    if (!PyArg_ParseTuple(args, "nnnKKKKKKKKKndiK", &P, &D, &F, &w_p, &phi_p, &dec_p, &ret_p,
                          &dur_p, &qn_p, &term_p, &act_p, &step_p, &step_stride, &gamma,
                          &use_gamma, &delta_p))
        return NULL;
    double *w = F64(w_p), *delta = F64(delta_p);
    const double *phi = F64(phi_p), *ret = F64(ret_p), *q_next = F64(qn_p), *step = F64(step_p);
    const int64_t *decision = I64(dec_p), *duration = I64(dur_p);
    const uint8_t *terminal = U8(term_p), *active = U8(act_p);
    for (Py_ssize_t p = 0; p < P; p++) {
        if (!active[p]) {
            delta[p] = 0.0;
            continue;
        }
        double *wd = w + (p * D + decision[p]) * F;
        const double *x = phi + p * F;
        double q_sa = dot(wd, x, F);
        double boot = use_gamma ? pow(gamma, (double)duration[p]) * q_next[p] : q_next[p];
        if (terminal[p]) boot = 0.0;
        double d = (ret[p] + boot) - q_sa;
        for (Py_ssize_t f = 0; f < F; f++) wd[f] += step[f * step_stride] * (d * x[f]);
        delta[p] = d;
    }
    Py_RETURN_NONE;
}

/* intra_option(P, K, A, Fo, w, code, next_code, action, reward, terminated, mask, reached,
 * alpha, gamma, completion, delta): for every (p, k) in mask, target = (r + C [reached])
 * + gamma max_a w[p, k, a] . next_code[p] [neither reached nor terminated], delta = target
 * - w[p, k, a_p] . code[p], w[p, k, a_p] += (alpha * delta) * code[p]; delta 0 elsewhere. */
static PyObject *intra_option(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, A, Fo;
    unsigned long long w_p, code_p, next_p, act_p, r_p, term_p, mask_p, reach_p, delta_p;
    double alpha, gamma, completion;
    if (!PyArg_ParseTuple(args, "nnnnKKKKKKKKdddK", &P, &K, &A, &Fo, &w_p, &code_p, &next_p,
                          &act_p, &r_p, &term_p, &mask_p, &reach_p, &alpha, &gamma,
                          &completion, &delta_p))
        return NULL;
    if (A > MAX_CHOICES) {
        PyErr_SetString(PyExc_ValueError, "intra_option: at most 64 actions");
        return NULL;
    }
    double *w = F64(w_p), *delta = F64(delta_p);
    const double *code = F64(code_p), *next_code = F64(next_p), *reward = F64(r_p);
    const int64_t *action = I64(act_p);
    const uint8_t *terminated = U8(term_p), *mask = U8(mask_p), *reached = U8(reach_p);
    double q[MAX_CHOICES];
    for (Py_ssize_t p = 0; p < P; p++) {
        const double *x = code + p * Fo, *x1 = next_code + p * Fo;
        for (Py_ssize_t k = 0; k < K; k++) {
            Py_ssize_t s = p * K + k;
            if (!mask[s]) {
                delta[s] = 0.0;
                continue;
            }
            double *wk = w + s * A * Fo;
            double boot = 0.0;
            if (!reached[s] && !terminated[p]) {
                for (Py_ssize_t a = 0; a < A; a++) q[a] = dot(wk + a * Fo, x1, Fo);
                boot = gamma * masked_max(q, NULL, A);
            }
            double target = (reward[p] + (reached[s] ? completion : 0.0)) + boot;
            double *wa = wk + action[p] * Fo;
            double d = target - dot(wa, x, Fo);
            double scale = alpha * d;
            for (Py_ssize_t f = 0; f < Fo; f++) wa[f] = wa[f] + scale * x[f];
            delta[s] = d;
        }
    }
    Py_RETURN_NONE;
}

/* q_rows(n, index, D, F, w, phi, decision, out): out[i] = w[p, decision[p]] . phi[p] with
 * p = index[i]. */
static PyObject *q_rows(PyObject *self, PyObject *args)
{
    Py_ssize_t n, D, F;
    unsigned long long idx_p, w_p, phi_p, dec_p, out_p;
    if (!PyArg_ParseTuple(args, "nKnnKKKK", &n, &idx_p, &D, &F, &w_p, &phi_p, &dec_p, &out_p))
        return NULL;
    const int64_t *index = I64(idx_p), *decision = I64(dec_p);
    const double *w = F64(w_p), *phi = F64(phi_p);
    double *out = F64(out_p);
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t p = index[i];
        out[i] = dot(w + (p * D + decision[p]) * F, phi + p * F, F);
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"choose", choose, METH_VARARGS, "Top-level values and epsilon-greedy decisions."},
    {"act", act, METH_VARARGS, "Primitive actions: the decision's, or the option's choice."},
    {"smdp", smdp, METH_VARARGS, "SMDP Sarsa updates of the decisions that ended."},
    {"intra_option", intra_option, METH_VARARGS, "Intra-option Q-learning updates."},
    {"q_rows", q_rows, METH_VARARGS, "Q(s, d) of some agents."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_hierarchical_native",
                                    "Compiled hierarchical agent step (see "
                                    "native_hierarchical.py).", -1, methods};

PyMODINIT_FUNC PyInit__hierarchical_native(void) { return PyModule_Create(&module); }
