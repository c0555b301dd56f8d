/* The hierarchical agent's per-step arithmetic, compiled (see hierarchical.py).
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

/* Decisions (primitives + option slots) and option actions per row, on the stack; exported as
 * the module's MAX_CHOICES, above which the Python side takes the torch path. */
#define MAX_CHOICES 1024

#define F64(p) ((double *)(uintptr_t)(p))
#define I64(p) ((int64_t *)(uintptr_t)(p))
#define U8(p) ((uint8_t *)(uintptr_t)(p))

/* ------------------------------------------------------------------ one agent's pieces */

/* Top-level values of the decisions needed at a state (the first `dense` whenever any of them
 * is available, the others where available; all 0 unless `decide`), then the epsilon-greedy
 * decision among the available ones. As LinearQHead.forward_mask + epsilon_greedy. */
NATIVE_CLONES static int64_t choose_row(const double *w, const double *phi, const uint8_t *ok, Py_ssize_t D,
                          Py_ssize_t F, Py_ssize_t dense, int decide, double epsilon,
                          const double *u, double *q)
{
    int dense_needed = 0;
    for (Py_ssize_t d = 0; d < dense; d++) dense_needed |= ok[d];
    for (Py_ssize_t d = 0; d < D; d++) {
        int need = decide && (d < dense ? dense_needed : ok[d]);
        q[d] = need ? dot(w + d * F, phi, F) : 0.0;
    }
    return epsilon_greedy(q, ok, D, epsilon, u[0], u[1]);
}

/* The primitive action: min(decision, A - 1), or option `option`'s epsilon-greedy action by
 * its values w_opt[option, a] . code. `known` (or NULL): those values for every action but
 * `stale`, already computed from the same weights and code (the step's intra-option update
 * of this option valued s' before changing row `stale` alone), so only that row is redone. */
NATIVE_CLONES static int64_t act_row(const double *w_opt, const double *code, int64_t decision,
                       int64_t option, Py_ssize_t A, Py_ssize_t Fo, double epsilon,
                       const double *u, const double *known, int64_t stale)
{
    double q[MAX_CHOICES];
    if (option < 0) return decision < A - 1 ? decision : A - 1;
    const double *wk = w_opt + option * A * Fo;
    for (Py_ssize_t a = 0; a < A; a++)
        q[a] = known && a != stale ? known[a] : dot(wk + a * Fo, code, Fo);
    return epsilon_greedy(q, NULL, A, epsilon, u[0], u[1]);
}

/* SMDP Sarsa: delta = (R + gamma^k q_next [not terminal]) - wd . phi, wd += step * (delta phi).
 * gamma^k is libm's pow, as Python's gamma ** k in SarsaUpdate's table. */
NATIVE_CLONES static double smdp_row(double *wd, const double *phi, Py_ssize_t F, double R, int64_t k,
                       double q_next, int terminal, const double *step, Py_ssize_t stride,
                       double gamma, int use_gamma)
{
    double q_sa = dot(wd, phi, F);
    double boot = use_gamma ? pow(gamma, (double)k) * q_next : q_next;
    if (terminal) boot = 0.0;
    double delta = (R + boot) - q_sa;
    for (Py_ssize_t f = 0; f < F; f++) wd[f] += step[f * stride] * (delta * phi[f]);
    return delta;
}

/* Intra-option Q-learning of one option (weights wk [A, Fo]) from (s, a, r, s'):
 * target = (r + C [reached]) + gamma max_b wk[b] . x1 [neither reached nor terminated],
 * delta = target - wk[a] . x, wk[a] += (alpha delta) x. The values wk[b] . x1 go to q [A]
 * when computed (returns them in *valued = 1; the update then changes only q[a]'s row). */
NATIVE_CLONES static double intra_row(double *wk, const double *x, const double *x1, int64_t a, double r,
                        int reached, int terminated, Py_ssize_t A, Py_ssize_t Fo, double alpha,
                        double gamma, double completion, double *q, int *valued)
{
    double boot = 0.0;
    *valued = 0;
    if (!reached && !terminated) {
        *valued = 1;
        for (Py_ssize_t b = 0; b < A; b++) q[b] = dot(wk + b * Fo, x1, Fo);
        boot = gamma * masked_max(q, NULL, A);
    }
    double target = (r + (reached ? completion : 0.0)) + boot;
    double *wa = wk + a * Fo;
    double delta = target - dot(wa, x, Fo);
    double scale = alpha * delta;
    for (Py_ssize_t f = 0; f < Fo; f++) wa[f] = wa[f] + scale * x[f];
    return delta;
}

/* ------------------------------------------------------------------ batched pieces */

/* choose(P, D, F, w, phi, available, rows, dense, u, u_stride, epsilon, q, decision):
 * choose_row for every agent (values only for `rows`), w [P, D, F], u [P, >= 2] rows
 * u_stride apart. */
NATIVE_CLONES static PyObject *choose(PyObject *self, PyObject *args)
{
    Py_ssize_t P, D, F, dense, u_stride;
    unsigned long long w_p, phi_p, av_p, rows_p, u_p, q_p, dec_p;
    double epsilon;
    if (!PyArg_ParseTuple(args, "nnnKKKKnKndKK", &P, &D, &F, &w_p, &phi_p, &av_p, &rows_p,
                          &dense, &u_p, &u_stride, &epsilon, &q_p, &dec_p))
        return NULL;
    if (D > MAX_CHOICES) {
        PyErr_Format(PyExc_ValueError, "choose: at most %d decisions", MAX_CHOICES);
        return NULL;
    }
    const double *w = F64(w_p), *phi = F64(phi_p), *u = F64(u_p);
    const uint8_t *available = U8(av_p), *rows = U8(rows_p);
    double *q = F64(q_p);
    int64_t *decision = I64(dec_p);
    for (Py_ssize_t p = 0; p < P; p++)
        decision[p] = choose_row(w + p * D * F, phi + p * F, available + p * D, D, F, dense,
                                 rows[p], epsilon, u + p * u_stride, q + p * D);
    Py_RETURN_NONE;
}

/* act(P, K, A, Fo, w, code, rows, decision, option, u, u_stride, epsilon, action): act_row for
 * the rows in `rows` (w [P, K, A, Fo]); other rows keep their action. */
NATIVE_CLONES static PyObject *act(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, A, Fo, u_stride;
    unsigned long long w_p, code_p, rows_p, dec_p, opt_p, u_p, act_p;
    double epsilon;
    if (!PyArg_ParseTuple(args, "nnnnKKKKKKndK", &P, &K, &A, &Fo, &w_p, &code_p, &rows_p,
                          &dec_p, &opt_p, &u_p, &u_stride, &epsilon, &act_p))
        return NULL;
    if (A > MAX_CHOICES) {
        PyErr_Format(PyExc_ValueError, "act: at most %d actions", MAX_CHOICES);
        return NULL;
    }
    const double *w = F64(w_p), *code = F64(code_p), *u = F64(u_p);
    const uint8_t *rows = U8(rows_p);
    const int64_t *decision = I64(dec_p), *option = I64(opt_p);
    int64_t *action = I64(act_p);
    for (Py_ssize_t p = 0; p < P; p++)
        if (rows[p])
            action[p] = act_row(w + p * K * A * Fo, code + p * Fo, decision[p], option[p], A,
                                Fo, epsilon, u + p * u_stride, NULL, 0);
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------ the whole transition */

/* step(P, K, A, F, Fo, w, w_opt, obs, code, contains, phi, decision, option, action, ret,
 *      duration, next_obs, reward, terminated, truncated, stepped, contains_next, reached,
 *      phi_next, next_code, columns, status, u, epsilon, option_epsilon, gamma, use_gamma,
 *      max_option_steps, alpha_o, completion, step, step_stride, executable_from,
 *      out_obs, out_code, out_contains, out_phi, out_decision, out_option, out_action,
 *      out_ret, out_duration, q, d_next, decision_ended, option_delta, smdp_delta,
 *      info_duration, info_return, started, value, fail_boot, state_phi, interrupt, own,
 *      ipo_primitives, own_next, leave_from)
 *
 * HierarchicalAgent.transition for every row, given what needs torch or Python at s'
 * (memberships, targets, features, uniforms [P, 4]): the intra-option updates, the decision's
 * return and duration, the end of executions, the top-level choice at s', the SMDP update, the
 * new state and the next primitive action, in the torch path's order. The state at s' goes to
 * the out_ arrays. out_code and out_phi may be code and phi themselves (the agent keeps these
 * two large arrays and updates them in place: each row is read before it is written, and the
 * decision's features are copied only for new decisions); the other out_ arrays must be
 * fresh. Rows outside `stepped` keep their state. `status` [P, K]: live slots are != 0,
 * available ones >= executable_from (and contain s'). q [P, D]: the values the decision at s'
 * was taken with (rows whose decision ended; 0 elsewhere); `started`: rows starting an option.
 * A counts both the primitive decisions and the option heads' actions. The option heads' code
 * of s' is next_code [P, Fo], or when that is 0 the columns [Fo] (int64) of phi_next (the
 * heads' Fourier features among the top level's, shared_fourier_columns). value [P] (or 0):
 * Q(s', d) of the decision d in force after the step, for stepped rows (skill chaining's
 * gestation samples). state_phi [P, F] (or 0): phi(s) of the current state, for intra-option
 * learning of the top-level primitive values (HierarchicalAgent's intra_option_primitives):
 * a step taken inside an option moves w[a] . phi(s) toward r + gamma max_d Q(s', d) over the
 * decisions available at s' (as smdp_row with k = 1), or over the primitives only where
 * ipo_primitives; the row then holds phi(s').
 * interrupt: an executing option stops at s' where it is no longer the greedy decision
 * (HierarchicalAgent's interruption). own [P, K]: s in each option's own set (before the
 * no-overlap narrowing). The live options a transition from s updates are
 * objectives.q_learning.option_update_mask's: the executing one wherever s is, the others
 * where own holds. own_next [P, K] (or 0): each option's own set at s'; where given, an
 * executing option whose status is at least leave_from ends at an s' outside its own set
 * (HierarchicalAgent's end_outside_set). */
NATIVE_CLONES static PyObject *step(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, A, F, Fo, step_stride;
    unsigned long long w_p, wo_p, obs_p, code_p, con_p, phi_p, dec_p, opt_p, act_p, ret_p,
        dur_p, nobs_p, rew_p, term_p, trunc_p, st_p, conn_p, reach_p, phin_p, coden_p,
        cols_p, status_p, u_p, step_p, o_obs, o_code, o_con, o_phi, o_dec, o_opt, o_act, o_ret,
        o_dur, q_p, dn_p, de_p, od_p, sd_p, id_p, ir_p, started_p, value_p, sphi_p, own_p,
        own_next_p;
    double epsilon, option_epsilon, gamma, alpha_o, completion;
    int use_gamma, fail_boot, interrupt, ipo_primitives;
    long long max_option_steps, executable_from, leave_from;
    if (!PyArg_ParseTuple(args,
                          "nnnnnKKKKKKKKKKKKKKKKKKKKKKKdddiLddKnLKKKKKKKKKKKKKKKKKKiKiKiKL",
                          &P, &K, &A, &F, &Fo, &w_p, &wo_p, &obs_p, &code_p, &con_p, &phi_p,
                          &dec_p, &opt_p, &act_p, &ret_p, &dur_p, &nobs_p, &rew_p, &term_p,
                          &trunc_p, &st_p, &conn_p, &reach_p, &phin_p, &coden_p, &cols_p,
                          &status_p, &u_p, &epsilon, &option_epsilon, &gamma, &use_gamma,
                          &max_option_steps, &alpha_o, &completion, &step_p, &step_stride,
                          &executable_from, &o_obs, &o_code, &o_con, &o_phi, &o_dec, &o_opt,
                          &o_act, &o_ret, &o_dur, &q_p, &dn_p, &de_p, &od_p, &sd_p, &id_p,
                          &ir_p, &started_p, &value_p, &fail_boot, &sphi_p, &interrupt,
                          &own_p, &ipo_primitives, &own_next_p, &leave_from))
        return NULL;
    Py_ssize_t D = A + K;
    if (D > MAX_CHOICES) {
        PyErr_Format(PyExc_ValueError, "step: at most %d decisions", MAX_CHOICES);
        return NULL;
    }
    double *w = F64(w_p), *w_opt = F64(wo_p);
    const double *obs = F64(obs_p), *code = F64(code_p), *phi = F64(phi_p), *ret = F64(ret_p);
    const double *next_obs = F64(nobs_p), *reward = F64(rew_p), *phi_next = F64(phin_p);
    const double *next_code = F64(coden_p), *u = F64(u_p), *step_size = F64(step_p);
    const int64_t *columns = I64(cols_p);
    double *value = F64(value_p), *state_phi = F64(sphi_p);
    const int64_t *decision = I64(dec_p), *option = I64(opt_p), *action = I64(act_p);
    const int64_t *duration = I64(dur_p), *status = I64(status_p);
    const uint8_t *contains = U8(con_p), *terminated = U8(term_p), *truncated = U8(trunc_p);
    const uint8_t *stepped = U8(st_p), *contains_next = U8(conn_p), *reached = U8(reach_p);
    const uint8_t *own = U8(own_p), *own_next = U8(own_next_p);
    double *out_obs = F64(o_obs), *out_code = F64(o_code), *out_phi = F64(o_phi);
    double *out_ret = F64(o_ret), *q = F64(q_p), *option_delta = F64(od_p);
    double *smdp_delta = F64(sd_p), *info_return = F64(ir_p);
    int64_t *out_decision = I64(o_dec), *out_option = I64(o_opt), *out_action = I64(o_act);
    int64_t *out_duration = I64(o_dur), *d_next = I64(dn_p), *info_duration = I64(id_p);
    uint8_t *out_contains = U8(o_con), *decision_ended = U8(de_p), *started = U8(started_p);
    uint8_t ok[MAX_CHOICES];
    double *code_next = (double *)malloc(sizeof(double) * (size_t)(Fo > 0 ? Fo : 1));
    if (!code_next) return PyErr_NoMemory();

    for (Py_ssize_t p = 0; p < P; p++) {
        int go = stepped[p], term = go && terminated[p], ended = term || (go && truncated[p]);
        /* code_next: the code of s' (kept only if stepped), written to out_code last */
        if (next_code) {
            for (Py_ssize_t f = 0; f < Fo; f++) code_next[f] = next_code[p * Fo + f];
        } else {
            for (Py_ssize_t f = 0; f < Fo; f++) code_next[f] = phi_next[p * F + columns[f]];
        }
        const double *x = code + p * Fo, *x1 = code_next, *up = u + p * 4;
        const int64_t *st = status + p * K;
        const uint8_t *reach = reached + p * K, *in_next = contains_next + p * K;
        double r = go ? reward[p] : 0.0;

        /* Intra-option Q-learning (option_update_mask): every live option that is executing
         * or whose own set holds s. The executing option's values at s' are kept for its next
         * action (act_row). */
        double q_exec[MAX_CHOICES], q_other[MAX_CHOICES];
        int exec_valued = 0;
        for (Py_ssize_t k = 0; k < K; k++) {
            Py_ssize_t s = p * K + k;
            int valued = 0;
            option_delta[s] = go && (own[s] || k == option[p]) && st[k] != 0
                ? intra_row(w_opt + s * A * Fo, x, x1, action[p], r, reach[k], term, A, Fo,
                            alpha_o, gamma, completion, k == option[p] ? q_exec : q_other,
                            &valued)
                : 0.0;
            if (k == option[p]) exec_valued = valued;
        }

        /* The decision in force accumulates the (discounted) reward; has it ended? */
        double R = ret[p];
        int64_t k_steps = duration[p];
        if (go) {
            R = use_gamma ? R + pow(gamma, (double)k_steps) * r : R + r;
            k_steps += 1;
        }
        int executing = option[p] >= 0;
        int stops = executing && (reach[option[p]] || k_steps >= max_option_steps);
        /* end_outside_set: an execution also ends at an s' outside its option's own set */
        int leaves = own_next && executing && st[option[p]] >= leave_from
                     && !own_next[p * K + option[p]];
        int dec_end = go && (!executing || stops || ended || leaves);
        int inside = go && executing;  /* the option chose the action at s */

        /* Next top-level decision at s' (also the bootstrap decision d'). The values at s' are
         * needed where the decision ended, and inside options for the intra-option update of
         * the primitives (max_d Q(s', d)) and for interruption (Q(s', o) against it). */
        for (Py_ssize_t d = 0; d < D; d++)
            ok[d] = d < A ? 1 : (st[d - A] >= executable_from && in_next[d - A]);
        double *qp = q + p * D;
        int valued = dec_end || (inside && (state_phi || interrupt));
        int64_t dn = choose_row(w + p * D * F, phi_next + p * F, ok, D, F, A, valued,
                                epsilon, up, qp);
        /* Interruption: the option in force stops where it is no longer the greedy decision
         * (Q(s', o) below max_d Q(s', d)); the top level then takes d'. */
        if (interrupt && inside && !dec_end) {
            Py_ssize_t o = A + option[p];
            double q_o = ok[o] ? qp[o] : dot(w + (p * D + o) * F, phi_next + p * F, F);
            if (q_o < masked_max(qp, ok, D)) dec_end = 1;
        }
        decision_ended[p] = (uint8_t)dec_end;
        info_duration[p] = k_steps;
        info_return[p] = R;
        d_next[p] = dn;
        /* A timed-out execution bootstraps on the best primitive at s' (fail_boot), not on
         * d': d' is often the same optimistic option again (see failure_bootstrap). */
        double q_boot = qp[dn];
        if (fail_boot && executing && !reach[option[p]] && k_steps >= max_option_steps) {
            q_boot = qp[0];
            for (Py_ssize_t a = 1; a < A; a++) q_boot = qp[a] > q_boot ? qp[a] : q_boot;
        }
        /* Intra-option learning of the primitive the option took at s (a row other than the
         * option's, so the order of the two updates does not matter). */
        if (state_phi && inside)
            smdp_row(w + (p * D + action[p]) * F, state_phi + p * F, F, r, 1,
                     term ? 0.0 : masked_max(qp, ok, ipo_primitives ? A : D), term, step_size,
                     step_stride, gamma, use_gamma);
        if (state_phi && go)
            for (Py_ssize_t f = 0; f < F; f++) state_phi[p * F + f] = phi_next[p * F + f];
        smdp_delta[p] = dec_end ? smdp_row(w + (p * D + decision[p]) * F, phi + p * F, F, R,
                                           k_steps < 1 ? 1 : k_steps, q_boot, term, step_size,
                                           step_stride, gamma, use_gamma)
                                : 0.0;

        /* The state at s'. */
        const double *s_obs = go ? next_obs + p * 4 : obs + p * 4;
        for (int j = 0; j < 4; j++) out_obs[p * 4 + j] = s_obs[j];
        const double *c_new = go ? code_next : x;
        for (Py_ssize_t k = 0; k < K; k++)
            out_contains[p * K + k] = go ? in_next[k] : contains[p * K + k];
        int fresh = dec_end && !ended;
        int64_t dec = fresh ? dn : decision[p];
        int64_t opt = ended ? -1 : fresh ? (dn >= A ? dn - A : -1) : option[p];
        const double *phi_new = fresh ? phi_next + p * F : phi + p * F;
        if (out_phi + p * F != phi_new)
            for (Py_ssize_t f = 0; f < F; f++) out_phi[p * F + f] = phi_new[f];
        out_ret[p] = fresh ? 0.0 : R;
        out_duration[p] = fresh ? 0 : k_steps;
        out_decision[p] = dec;
        out_option[p] = opt;
        started[p] = (uint8_t)(fresh && dn >= A);
        /* The same option going on from s' (code x1): its values were taken above. */
        int reuse = exec_valued && !fresh && opt == option[p];
        out_action[p] = go && !ended
            ? act_row(w_opt + p * K * A * Fo, c_new, dec, opt, A, Fo, option_epsilon, up + 2,
                      reuse ? q_exec : NULL, action[p])
            : action[p];
        if (value)
            value[p] = !go      ? 0.0
                       : dec_end ? qp[dec]
                                 : dot(w + (p * D + dec) * F, phi_next + p * F, F);
        if (out_code + p * Fo != c_new)
            for (Py_ssize_t f = 0; f < Fo; f++) out_code[p * Fo + f] = c_new[f];
    }
    free(code_next);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"choose", choose, METH_VARARGS, "Top-level values and epsilon-greedy decisions."},
    {"act", act, METH_VARARGS, "Primitive actions: the decision's, or the option's choice."},
    {"step", step, METH_VARARGS, "HierarchicalAgent.transition for every row."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_hierarchical",
                                    "Compiled hierarchical agent step (see "
                                    "hierarchical.py).", -1, methods};

PyMODINIT_FUNC PyInit__hierarchical(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntMacro(m, MAX_CHOICES) < 0) Py_CLEAR(m);
    return m;
}
