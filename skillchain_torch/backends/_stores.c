/* The initiation classifiers' example stores, compiled (see options/example_store.py and
 * options/examples.py): add_examples's placement of each new example (while a slot has room,
 * in order; then a ring, or a reservoir draw from examples.reservoir_uniform's SplitMix64
 * stream), and the examples of ended executions (ExecutionTrace.examples). Integers are
 * copied and hashed, so the bits are the torch path's.
 *
 * Why it exists: a finished execution stores up to 250 examples, one at a time in order (each
 * placement depends on the last), which in torch is a loop of small operations per example.
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

/* The classifier's stores, as passed to store and store_executions after their own
 * arguments: seeds, generation, salt, flags, seen, examples, labels, count, touched. flags:
 * bit 0 ring replacement, bit 1 keep negatives (a positive never replaces a stored negative),
 * bit 2 store failures (a negative always enters a full store: examples.failure_place). */
typedef struct {
    const int64_t *seeds, *generation;
    uint64_t salt;
    int ring, keep_negatives, store_failures;
    int64_t *seen, *count;
    double *examples;
    uint8_t *labels, *touched;
} Stores;

#define STORES_FORMAT "KKLiKKKKK"

static Stores make_stores(unsigned long long seeds_p, unsigned long long gen_p, long long salt,
                          int ring, unsigned long long seen_p, unsigned long long ex_p,
                          unsigned long long lab_p, unsigned long long cnt_p,
                          unsigned long long t_p)
{
    Stores st = {(const int64_t *)(uintptr_t)seeds_p, (const int64_t *)(uintptr_t)gen_p,
                 (uint64_t)salt, ring & 1, (ring >> 1) & 1, (ring >> 2) & 1,
                 (int64_t *)(uintptr_t)seen_p,
                 (int64_t *)(uintptr_t)cnt_p,
                 (double *)(uintptr_t)ex_p, (uint8_t *)(uintptr_t)lab_p,
                 (uint8_t *)(uintptr_t)t_p};
    return st;
}

/* The reservoir's draw for the example numbered `index` of store s (agent p, slot k):
 * min(floor(u (index + 1)), index), u = examples.reservoir_uniform(seed, k, generation, index). */
static int64_t draw_place(const Stores *st, int64_t p, int64_t k, int64_t s, int64_t index)
{
    uint64_t key = splitmix64((uint64_t)st->seeds[p] ^ st->salt);
    key = splitmix64(key + (uint64_t)k * GOLDEN_GAMMA);
    key = splitmix64(key + (uint64_t)st->generation[s] * GOLDEN_GAMMA);
    uint64_t bits = splitmix64(key + (uint64_t)index * GOLDEN_GAMMA) >> 11;
    double u = (double)(int64_t)bits * 0x1p-53;
    int64_t draw = (int64_t)floor(u * (double)(index + 1));
    return draw > index ? index : draw;
}

/* Store one example of agent p's slot k as add_examples does: the example numbered `seen` of
 * its slot takes place `seen` while the slot has room, then (ring) place seen % C, or
 * (reservoir) place min(floor(u (seen + 1)), seen) if that is below C, with
 * u = examples.reservoir_uniform(seed, slot, generation, seen); seen, count (= min(seen, C))
 * and touched follow. With store_failures a negative of a full store is never rejected. */
static void store_in(const Stores *st, int64_t p, int64_t k, int64_t K, int64_t C,
                     const double *point, int label)
{
    int64_t s = p * K + k;
    int64_t index = st->seen[s]++;
    int64_t place = index;
    if (st->ring) {
        place = index % C;
    } else if (index >= C) {
        int64_t draw = draw_place(st, p, k, s, index);
        place = draw < C ? draw : -1;
    }
    /* keep negatives: a positive landing on a stored negative is dropped instead */
    if (place >= 0 && label && st->keep_negatives && index >= C && !st->labels[s * C + place])
        place = -1;
    /* store failures: a negative is never rejected; from the drawn place (draw mod C) it takes
     * the first stored positive, cyclically, or the drawn place if none is left */
    if (!label && st->store_failures && !st->ring && index >= C) {
        int64_t first = draw_place(st, p, k, s, index) % C;
        place = first;
        for (int64_t j = 0; j < C; j++) {
            int64_t q = (first + j) % C;
            if (st->labels[s * C + q]) { place = q; break; }
        }
    }
    st->touched[s] = 1;
    st->count[s] = st->seen[s] < C ? st->seen[s] : C;
    if (place < 0) return;
    double *e = st->examples + (s * C + place) * OBS_DIM;
    for (int j = 0; j < OBS_DIM; j++) e[j] = point[j];
    st->labels[s * C + place] = (uint8_t)(label != 0);
}

/* store(P, K, C, n, agents, slots, obs, new_labels, <stores>): add_examples's stores of n
 * examples (obs [n, 4], new_labels uint8 [n]) for (agents, slots) (int64 [n]), one after the
 * other (as examples.store_places has it). Returns -1 (nothing written) if an agent or slot
 * index is out of range, else 0. */
static PyObject *store(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, C, n;
    unsigned long long a_p, k_p, obs_p, nl_p, seeds_p, gen_p, seen_p, ex_p, lab_p, cnt_p, t_p;
    long long salt;
    int ring;
    if (!PyArg_ParseTuple(args, "nnnnKKKK" STORES_FORMAT, &P, &K, &C, &n, &a_p, &k_p, &obs_p,
                          &nl_p, &seeds_p, &gen_p, &salt, &ring, &seen_p, &ex_p, &lab_p, &cnt_p,
                          &t_p))
        return NULL;
    Stores st = make_stores(seeds_p, gen_p, salt, ring, seen_p, ex_p, lab_p, cnt_p, t_p);
    const int64_t *agents = (const int64_t *)(uintptr_t)a_p;
    const int64_t *slots = (const int64_t *)(uintptr_t)k_p;
    const double *obs = (const double *)(uintptr_t)obs_p;
    const uint8_t *new_labels = (const uint8_t *)(uintptr_t)nl_p;
    for (Py_ssize_t i = 0; i < n; i++)
        if (agents[i] < 0 || agents[i] >= P || slots[i] < 0 || slots[i] >= K)
            return PyLong_FromLong(-1);
    for (Py_ssize_t i = 0; i < n; i++)
        store_in(&st, agents[i], slots[i], K, C, obs + i * OBS_DIM, new_labels[i]);
    return PyLong_FromLong(0);
}

/* store_executions(P, K, C, T, states, slot, duration, success, failure, <stores>): the
 * examples of ended executions, as ExecutionTrace.examples lists them (agent by agent): the
 * first min(duration, T) states [P, T, 4] of a success are positives, the first state of a
 * failure a negative, stored in slot[p]. Returns the number of examples. */
static PyObject *store_executions(PyObject *self, PyObject *args)
{
    Py_ssize_t P, K, C, T;
    unsigned long long st_p, k_p, d_p, ok_p, bad_p, seeds_p, gen_p, seen_p, ex_p, lab_p, cnt_p,
        t_p;
    long long salt;
    int ring;
    if (!PyArg_ParseTuple(args, "nnnnKKKKK" STORES_FORMAT, &P, &K, &C, &T, &st_p, &k_p, &d_p,
                          &ok_p, &bad_p, &seeds_p, &gen_p, &salt, &ring, &seen_p, &ex_p, &lab_p,
                          &cnt_p, &t_p))
        return NULL;
    Stores st = make_stores(seeds_p, gen_p, salt, ring, seen_p, ex_p, lab_p, cnt_p, t_p);
    const double *states = (const double *)(uintptr_t)st_p;
    const int64_t *slot = (const int64_t *)(uintptr_t)k_p;
    const int64_t *duration = (const int64_t *)(uintptr_t)d_p;
    const uint8_t *success = (const uint8_t *)(uintptr_t)ok_p;
    const uint8_t *failure = (const uint8_t *)(uintptr_t)bad_p;
    long stored = 0;
    for (Py_ssize_t p = 0; p < P; p++) {
        const double *trajectory = states + p * T * OBS_DIM;
        if (success[p]) {
            int64_t steps = duration[p] < T ? duration[p] : T;
            for (int64_t t = 0; t < steps; t++, stored++)
                store_in(&st, p, slot[p], K, C, trajectory + t * OBS_DIM, 1);
        } else if (failure[p]) {
            store_in(&st, p, slot[p], K, C, trajectory, 0);
            stored++;
        }
    }
    return PyLong_FromLong(stored);
}

static PyMethodDef methods[] = {
    {"store", store, METH_VARARGS, "A classifier's example stores, one example at a time."},
    {"store_executions", store_executions, METH_VARARGS,
     "The examples of ended executions into a classifier's stores."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_stores",
                                    "Compiled initiation-set example stores (see examples.py).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__stores(void) { return PyModule_Create(&module); }
