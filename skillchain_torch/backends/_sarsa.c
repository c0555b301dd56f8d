/* The flat Sarsa agent's per-step arithmetic, compiled (see sarsa.py).
 *
 * Why it exists: at P = 100 the torch path makes ~20 passes over [P, 625] arrays a step
 * (products, sums, gathers, scatters), and at P = 1 it pays ~40 operations of a few
 * microseconds each. Here each agent's row is one pass: its Q values, its epsilon-greedy
 * decision, its Sarsa update.
 *
 * Arithmetic: the features come from FourierBasis. Dot products and the epsilon-greedy rule are
 * native_maths.h's (the dot products in a fixed order of their own: deterministic, independent
 * of the batch, not torch's bits; the rule is policies/epsilon_greedy.py's, decision for
 * decision). The update keeps SarsaUpdate's expression: w[a] += step * (delta * phi),
 * delta = (r + gamma q') - q. Compiled with -ffp-contract=off: no fused multiply-adds.
 *
 * Weights are agent-major [n, D, F] (the agent's working LinearQHead). Every array argument is
 * an address (torch.Tensor.data_ptr()); all arrays are contiguous.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

#include "native_maths.h"  /* dot, epsilon_greedy */

#define MAX_DECISIONS 16

/* w[a] += step * (delta * phi), delta = (r + boot) - w[a] . phi */
static void learn_row(double *wa, const double *phi, long F, double reward, double q_next,
                      int terminal, const double *step, long step_stride, double gamma,
                      int use_gamma)
{
    double q_sa = dot(wa, phi, F);
    double boot = terminal ? 0.0 : (use_gamma ? gamma * q_next : q_next);
    double delta = (reward + boot) - q_sa;
    for (long f = 0; f < F; f++) wa[f] += step[f * step_stride] * (delta * phi[f]);
}

/* linear_q(n, D, F, w, rows, phi, q): q[i, d] = w[r_i, d] . phi[i], with r_i = rows[i] (or i
 * when rows is 0). w is [N, D, F]; q is [n, D]. */
NATIVE_CLONES static PyObject *linear_q(PyObject *self, PyObject *args)
{
    Py_ssize_t n, D, F;
    unsigned long long w_p, rows_p, phi_p, q_p;
    if (!PyArg_ParseTuple(args, "nnnKKKK", &n, &D, &F, &w_p, &rows_p, &phi_p, &q_p))
        return NULL;
    const double *w = (const double *)(uintptr_t)w_p, *phi = (const double *)(uintptr_t)phi_p;
    const int64_t *rows = (const int64_t *)(uintptr_t)rows_p;
    double *q = (double *)(uintptr_t)q_p;
    for (Py_ssize_t i = 0; i < n; i++) {
        long r = rows ? (long)rows[i] : (long)i;
        for (Py_ssize_t d = 0; d < D; d++)
            q[i * D + d] = dot(w + (r * D + d) * F, phi + i * F, F);
    }
    Py_RETURN_NONE;
}

/* sarsa_learn(n, D, F, w, phi, action, reward, q_next, terminated, step, step_stride, gamma,
 * use_gamma): one Sarsa update of row i's action[i] (terminated: uint8 [n] or 0). */
NATIVE_CLONES static PyObject *sarsa_learn(PyObject *self, PyObject *args)
{
    Py_ssize_t n, D, F, step_stride;
    unsigned long long w_p, phi_p, a_p, r_p, qn_p, t_p, step_p;
    double gamma;
    int use_gamma;
    if (!PyArg_ParseTuple(args, "nnnKKKKKKKndi", &n, &D, &F, &w_p, &phi_p, &a_p, &r_p, &qn_p,
                          &t_p, &step_p, &step_stride, &gamma, &use_gamma))
        return NULL;
    double *w = (double *)(uintptr_t)w_p;
    const double *phi = (const double *)(uintptr_t)phi_p, *reward = (const double *)(uintptr_t)r_p;
    const double *q_next = (const double *)(uintptr_t)qn_p, *step = (const double *)(uintptr_t)step_p;
    const int64_t *action = (const int64_t *)(uintptr_t)a_p;
    const uint8_t *terminated = (const uint8_t *)(uintptr_t)t_p;
    for (Py_ssize_t i = 0; i < n; i++)
        learn_row(w + (i * D + action[i]) * F, phi + i * F, F, reward[i], q_next[i],
                  terminated ? terminated[i] : 0, step, step_stride, gamma, use_gamma);
    Py_RETURN_NONE;
}

/* sarsa_observe(n, D, F, w, phi, phi_next, action, reward, uniforms, u_stride, u_offset,
 * epsilon, step, step_stride, gamma, use_gamma, next_action): for each row, Q(s', .) with the
 * weights before this step's update, the epsilon-greedy choice a' from the row's uniforms
 * (u0, u1) = uniforms[i * u_stride + u_offset + (0, 1)], then the Sarsa update of (s, a) toward
 * r + gamma Q(s', a'). Writes a' to next_action. */
NATIVE_CLONES static PyObject *sarsa_observe(PyObject *self, PyObject *args)
{
    Py_ssize_t n, D, F, u_stride, u_offset, step_stride;
    unsigned long long w_p, phi_p, phi1_p, a_p, r_p, u_p, step_p, out_p;
    double epsilon, gamma;
    int use_gamma;
    if (!PyArg_ParseTuple(args, "nnnKKKKKKnndKndiK", &n, &D, &F, &w_p, &phi_p, &phi1_p, &a_p,
                          &r_p, &u_p, &u_stride, &u_offset, &epsilon, &step_p, &step_stride,
                          &gamma, &use_gamma, &out_p))
        return NULL;
    if (D > MAX_DECISIONS) {
        PyErr_SetString(PyExc_ValueError, "sarsa_observe: at most 16 decisions");
        return NULL;
    }
    double *w = (double *)(uintptr_t)w_p;
    const double *phi = (const double *)(uintptr_t)phi_p;
    const double *phi1 = (const double *)(uintptr_t)phi1_p;
    const double *reward = (const double *)(uintptr_t)r_p, *step = (const double *)(uintptr_t)step_p;
    const double *uniforms = (const double *)(uintptr_t)u_p;
    const int64_t *action = (const int64_t *)(uintptr_t)a_p;
    int64_t *next_action = (int64_t *)(uintptr_t)out_p;
    double q[MAX_DECISIONS];
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *p1 = phi1 + i * F, *u = uniforms + i * u_stride + u_offset;
        double *wi = w + i * D * F;
        for (Py_ssize_t d = 0; d < D; d++) q[d] = dot(wi + d * F, p1, F);
        int64_t a1 = epsilon_greedy(q, NULL, D, epsilon, u[0], u[1]);
        learn_row(wi + action[i] * F, phi + i * F, F, reward[i], q[a1], 0, step, step_stride,
                  gamma, use_gamma);
        next_action[i] = a1;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"linear_q", linear_q, METH_VARARGS, "Q values of some rows."},
    {"sarsa_learn", sarsa_learn, METH_VARARGS, "One Sarsa update per row."},
    {"sarsa_observe", sarsa_observe, METH_VARARGS, "Q(s', .), the choice a', the update."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_sarsa",
                                    "Compiled flat Sarsa step (see sarsa.py).", -1, methods};

PyMODINIT_FUNC PyInit__sarsa(void) { return PyModule_Create(&module); }
