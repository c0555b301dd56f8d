/* Skill chaining's per-step bookkeeping, compiled (see discovery.py).
 *
 * Why it exists: every step, skill chaining derives each option's target event at s', the
 * no-overlap memberships, the events a transition triggered, the gestating options' samples
 * and the executions' state records, each a handful of small boolean tensor operations on
 * [P, K] arrays: ~0.5 ms a step for an agent on its own, for a few hundred boolean tests.
 * Everything here is booleans, copies and maxima, so the results are the torch path's bits.
 *
 * Every array argument is an address (torch.Tensor.data_ptr()) of a contiguous CPU tensor;
 * flags are uint8 (torch.bool), metadata int64.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define OBS_DIM 4
#define EMPTY 0
#define GESTATING 1
#define LEARNED 3

/* Option k's target event at a state: the parent's membership there for a chain link,
 * otherwise its base event's value (target_event < 0: none); false for empty slots. */
static int target_of(const int64_t *parent, const int64_t *target_event, const int64_t *status,
                     const uint8_t *base, Py_ssize_t E, const uint8_t *contains, Py_ssize_t k)
{
    if (status[k] == 0) return 0;
    if (parent[k] >= 0) return contains[parent[k]];
    if (target_event[k] < 0 || E == 0) return 0;
    return base[target_event[k] < E ? target_event[k] : E - 1];
}

/* target_indicator(P, K, E, parent, target_event, status, base_fired, contains, out) */
static PyObject *target_indicator(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, E;
    unsigned long long par_p, te_p, st_p, base_p, con_p, out_p;
    if (!PyArg_ParseTuple(args, "nnnKKKKKK", &P, &K, &E, &par_p, &te_p, &st_p, &base_p, &con_p,
                          &out_p))
        return NULL;
    const int64_t *parent = (const int64_t *)(uintptr_t)par_p;
    const int64_t *target_event = (const int64_t *)(uintptr_t)te_p;
    const int64_t *status = (const int64_t *)(uintptr_t)st_p;
    const uint8_t *base = (const uint8_t *)(uintptr_t)base_p;
    const uint8_t *contains = (const uint8_t *)(uintptr_t)con_p;
    uint8_t *out = (uint8_t *)(uintptr_t)out_p;
    for (Py_ssize_t p = 0; p < P; p++)
        for (Py_ssize_t k = 0; k < K; k++)
            out[p * K + k] = (uint8_t)target_of(parent + p * K, target_event + p * K,
                                                status + p * K, base + p * E, E,
                                                contains + p * K, k);
    Py_RETURN_NONE;
}

/* One agent's list of target events (K slots, E base events): base event e while fewer than
 * max_branching live options target it; slot j's set once LEARNED, while fewer than
 * max_branching target it. */
static void listed(const int64_t *par, const int64_t *te, const int64_t *st, Py_ssize_t K,
                   Py_ssize_t E, Py_ssize_t max_branching, uint8_t *base_on, uint8_t *slot_on)
{
    for (Py_ssize_t e = 0; e < E; e++) {
        Py_ssize_t n = 0;
        for (Py_ssize_t k = 0; k < K; k++) n += st[k] != 0 && par[k] < 0 && te[k] == e;
        base_on[e] = (uint8_t)(n < max_branching);
    }
    for (Py_ssize_t j = 0; j < K; j++) {
        Py_ssize_t n = 0;
        for (Py_ssize_t k = 0; k < K; k++) n += st[k] != 0 && par[k] == j;
        slot_on[j] = (uint8_t)(st[j] == LEARNED && n < max_branching);
    }
}

/* event_list(P, K, E, parent, target_event, status, max_branching, base_on, slot_on): each
 * agent's list of target events (see listed). */
static PyObject *event_list(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, E, max_branching;
    unsigned long long par_p, te_p, st_p, bo_p, so_p;
    if (!PyArg_ParseTuple(args, "nnnKKKnKK", &P, &K, &E, &par_p, &te_p, &st_p, &max_branching,
                          &bo_p, &so_p))
        return NULL;
    const int64_t *parent = (const int64_t *)(uintptr_t)par_p;
    const int64_t *target_event = (const int64_t *)(uintptr_t)te_p;
    const int64_t *status = (const int64_t *)(uintptr_t)st_p;
    uint8_t *base_on = (uint8_t *)(uintptr_t)bo_p, *slot_on = (uint8_t *)(uintptr_t)so_p;
    for (Py_ssize_t p = 0; p < P; p++)
        listed(parent + p * K, target_event + p * K, status + p * K, K, E, max_branching,
               base_on + p * E, slot_on + p * K);
    Py_RETURN_NONE;
}

/* exclude_overlap(P, K, contains, exclusion, trained, out): out[p, k] = contains[p, k] and no
 * j with exclusion[p, k, j] is a trained set holding the state. */
static PyObject *exclude_overlap(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K;
    unsigned long long con_p, ex_p, tr_p, out_p;
    if (!PyArg_ParseTuple(args, "nnKKKK", &P, &K, &con_p, &ex_p, &tr_p, &out_p)) return NULL;
    const uint8_t *contains = (const uint8_t *)(uintptr_t)con_p;
    const uint8_t *exclusion = (const uint8_t *)(uintptr_t)ex_p;
    const uint8_t *trained = (const uint8_t *)(uintptr_t)tr_p;
    uint8_t *out = (uint8_t *)(uintptr_t)out_p;
    for (Py_ssize_t p = 0; p < P; p++)
        for (Py_ssize_t k = 0; k < K; k++) {
            int in = contains[p * K + k];
            for (Py_ssize_t j = 0; in && j < K; j++)
                if (exclusion[(p * K + k) * K + j] && contains[p * K + j] && trained[p * K + j])
                    in = 0;
            out[p * K + k] = (uint8_t)in;
        }
    Py_RETURN_NONE;
}

/* record(P, T, rows, step, obs, states, ring): for each agent p in rows, the state obs[p] into
 * states [P, T, 4]: at step min(step[p], T - 1) (ring 0: ExecutionTrace.record), or at
 * step[p] % T, then step[p] += 1 (ring 1: RecentStates.record, the episode's last T states). */
static PyObject *record(PyObject *self, PyObject *args)
{
    Py_ssize_t P, T;
    unsigned long long rows_p, step_p, obs_p, states_p;
    int ring;
    if (!PyArg_ParseTuple(args, "nnKKKKi", &P, &T, &rows_p, &step_p, &obs_p, &states_p, &ring))
        return NULL;
    const uint8_t *rows = (const uint8_t *)(uintptr_t)rows_p;
    int64_t *step = (int64_t *)(uintptr_t)step_p;
    const double *obs = (const double *)(uintptr_t)obs_p;
    double *states = (double *)(uintptr_t)states_p;
    for (Py_ssize_t p = 0; p < P; p++) {
        if (!rows[p]) continue;
        int64_t t = ring ? step[p] % T : (step[p] < T - 1 ? step[p] : T - 1);
        for (int j = 0; j < OBS_DIM; j++) states[(p * T + t) * OBS_DIM + j] = obs[p * OBS_DIM + j];
        if (ring) step[p] += 1;
    }
    Py_RETURN_NONE;
}

/* copy_slots(P, K, n, slots, rows, slot, held, to_slots): for each agent p in rows (uint8
 * [P]), held[p] = slots[p, max(slot[p], 0)] (to_slots 0: keep an option's weights when its
 * execution starts) or the reverse (to_slots 1: put them back when it failed); slots is
 * float64 [P, K, n], held [P, n]. ExecutionTrace.start / drop_updates: copies, the same bits. */
static PyObject *copy_slots(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, n;
    unsigned long long slots_p, rows_p, slot_p, held_p;
    int to_slots;
    if (!PyArg_ParseTuple(args, "nnnKKKKi", &P, &K, &n, &slots_p, &rows_p, &slot_p, &held_p,
                          &to_slots))
        return NULL;
    double *slots = (double *)(uintptr_t)slots_p, *held = (double *)(uintptr_t)held_p;
    const uint8_t *rows = (const uint8_t *)(uintptr_t)rows_p;
    const int64_t *slot = (const int64_t *)(uintptr_t)slot_p;
    for (Py_ssize_t p = 0; p < P; p++) {
        if (!rows[p]) continue;
        int64_t k = slot[p] > 0 ? slot[p] : 0;
        double *in_slot = slots + (p * K + k) * n, *kept = held + p * n;
        if (to_slots)
            memcpy(in_slot, kept, sizeof(double) * (size_t)n);
        else
            memcpy(kept, in_slot, sizeof(double) * (size_t)n);
    }
    Py_RETURN_NONE;
}

/* outcomes(P, K, option, reached, duration, ended, terminated, max_steps, slot, success,
 * failure) -> int: executions.execution_outcome for the executions that ended (ended[p] and
 * option[p] >= 0): slot = max(option, 0); success: its target reached[p, slot] fired;
 * failure: it did not, and ran duration >= max_steps steps or the episode terminated.
 * Returns 0 if no execution ended, else 1 + 2 * (any failure). */
static PyObject *outcomes(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K;
    long long max_steps;
    unsigned long long opt_p, reach_p, dur_p, end_p, term_p, slot_p, ok_p, bad_p;
    if (!PyArg_ParseTuple(args, "nnKKKKKLKKK", &P, &K, &opt_p, &reach_p, &dur_p, &end_p,
                          &term_p, &max_steps, &slot_p, &ok_p, &bad_p))
        return NULL;
    const int64_t *option = (const int64_t *)(uintptr_t)opt_p;
    const int64_t *duration = (const int64_t *)(uintptr_t)dur_p;
    const uint8_t *reached = (const uint8_t *)(uintptr_t)reach_p;
    const uint8_t *ended = (const uint8_t *)(uintptr_t)end_p;
    const uint8_t *terminated = (const uint8_t *)(uintptr_t)term_p;
    int64_t *slot = (int64_t *)(uintptr_t)slot_p;
    uint8_t *success = (uint8_t *)(uintptr_t)ok_p, *failure = (uint8_t *)(uintptr_t)bad_p;
    int any = 0, any_failure = 0;
    for (Py_ssize_t p = 0; p < P; p++) {
        int64_t k = option[p] > 0 ? option[p] : 0;
        int done = ended[p] && option[p] >= 0, hit = reached[p * K + k];
        slot[p] = k;
        success[p] = (uint8_t)(done && hit);
        failure[p] = (uint8_t)(done && !hit && (duration[p] >= max_steps || terminated[p]));
        any |= done;
        any_failure |= failure[p];
    }
    return PyLong_FromLong(any ? 1 + 2 * any_failure : 0);
}

/* triggers(P, K, E, parent, target_event, status, base_now, base_next, contains,
 * contains_next, reached, stepped, sample, gestation_q, max_branching, out_gestation_q,
 * out_base_trig, out_slot_trig, out_base_now, out_hits[, blocked]) -> (bool, bool): for the
 * stepped rows, the base events and the LEARNED options' sets the transition entered (false at
 * s, true at s'), and the gestating options whose target it entered (out_hits) take max(their
 * sample, sample[p]); returns whether an event on its agent's list (see listed) was triggered
 * by an agent that may create (only those can: not one whose slots are all live and whose full
 * slots are logged, blocked[p], uint8 [P], 0: none given) and whether any gestating option's
 * target was entered. */
static PyObject *triggers(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, E, max_branching;
    unsigned long long par_p, te_p, st_p, bn_p, bx_p, con_p, conx_p, reach_p, step_p, sam_p,
        gq_p, ogq_p, obt_p, ost_p, obn_p, hit_p, blk_p = 0;
    if (!PyArg_ParseTuple(args, "nnnKKKKKKKKKKKnKKKKK|K", &P, &K, &E, &par_p, &te_p, &st_p,
                          &bn_p, &bx_p, &con_p, &conx_p, &reach_p, &step_p, &sam_p, &gq_p,
                          &max_branching, &ogq_p, &obt_p, &ost_p, &obn_p, &hit_p, &blk_p))
        return NULL;
    const uint8_t *blocked = (const uint8_t *)(uintptr_t)blk_p;
    uint8_t *base_on = (uint8_t *)malloc((size_t)(K + E + 1)), *slot_on = base_on + E;
    if (!base_on) return PyErr_NoMemory();
    const int64_t *parent = (const int64_t *)(uintptr_t)par_p;
    const int64_t *target_event = (const int64_t *)(uintptr_t)te_p;
    const int64_t *status = (const int64_t *)(uintptr_t)st_p;
    const uint8_t *base_now = (const uint8_t *)(uintptr_t)bn_p;
    const uint8_t *base_next = (const uint8_t *)(uintptr_t)bx_p;
    const uint8_t *contains = (const uint8_t *)(uintptr_t)con_p;
    const uint8_t *contains_next = (const uint8_t *)(uintptr_t)conx_p;
    const uint8_t *reached = (const uint8_t *)(uintptr_t)reach_p;
    const uint8_t *stepped = (const uint8_t *)(uintptr_t)step_p;
    const double *sample = (const double *)(uintptr_t)sam_p;
    const double *gestation_q = (const double *)(uintptr_t)gq_p;
    double *out_gq = (double *)(uintptr_t)ogq_p;
    uint8_t *base_trig = (uint8_t *)(uintptr_t)obt_p, *slot_trig = (uint8_t *)(uintptr_t)ost_p;
    uint8_t *out_base_now = (uint8_t *)(uintptr_t)obn_p, *hits = (uint8_t *)(uintptr_t)hit_p;
    int any = 0, any_hit = 0;
    for (Py_ssize_t p = 0; p < P; p++) {
        int go = stepped[p], fired = 0;
        const int64_t *par = parent + p * K, *te = target_event + p * K, *st = status + p * K;
        for (Py_ssize_t k = 0; k < K; k++) {
            Py_ssize_t s = p * K + k;
            double q = gestation_q[s];
            hits[s] = (uint8_t)(go && st[k] == GESTATING && reached[s]
                                && !target_of(par, te, st, base_now + p * E, E, contains + p * K, k));
            if (hits[s]) {
                /* torch.maximum: NaN if either is NaN */
                double x = sample[p];
                q = (isnan(q) || isnan(x)) ? NAN : (x > q ? x : q);
                any_hit = 1;
            }
            out_gq[s] = q;
            slot_trig[s] = (uint8_t)(go && !contains[s] && contains_next[s] && st[k] == LEARNED);
            fired |= slot_trig[s];
        }
        for (Py_ssize_t e = 0; e < E; e++) {
            Py_ssize_t s = p * E + e;
            base_trig[s] = (uint8_t)(go && !base_now[s] && base_next[s]);
            fired |= base_trig[s];
            out_base_now[s] = go ? base_next[s] : base_now[s];
        }
        if (!fired || any) continue;
        if (blocked && blocked[p]) { /* its full slots are logged: it creates nothing more */
            int full = 1;
            for (Py_ssize_t k = 0; k < K; k++) full &= st[k] != EMPTY;
            if (full) continue;
        }
        listed(par, te, st, K, E, max_branching, base_on, slot_on);
        for (Py_ssize_t k = 0; k < K; k++) any |= slot_trig[p * K + k] && slot_on[k];
        for (Py_ssize_t e = 0; e < E; e++) any |= base_trig[p * E + e] && base_on[e];
    }
    free(base_on);
    return Py_BuildValue("(OO)", any ? Py_True : Py_False, any_hit ? Py_True : Py_False);
}

static PyMethodDef methods[] = {
    {"outcomes", outcomes, METH_VARARGS, "Success and failure of the executions that ended."},
    {"target_indicator", target_indicator, METH_VARARGS, "Each option's target at a state."},
    {"exclude_overlap", exclude_overlap, METH_VARARGS, "Memberships under the overlap rule."},
    {"event_list", event_list, METH_VARARGS, "The target events on each agent's list."},
    {"record", record, METH_VARARGS, "Agents' states into the trace or the recent ring."},
    {"copy_slots", copy_slots, METH_VARARGS, "One option's weights per agent, kept or put back."},
    {"triggers", triggers, METH_VARARGS, "Entered events and gestation samples of a step."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_discovery",
                                    "Compiled skill-chaining bookkeeping (see "
                                    "discovery.py).", -1, methods};

PyMODINIT_FUNC PyInit__discovery(void) { return PyModule_Create(&module); }
