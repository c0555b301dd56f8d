/* CounterRNG's draws, compiled (see rng.py): the same SplitMix64 words, so the same bits.
 *
 * Why it exists: a draw is ~15 small int64 tensor operations (shifts, xors, products, the
 * counter update), ~0.1 ms a step for an agent on its own, where the arithmetic is a few
 * nanoseconds. uint64 arithmetic here wraps exactly as torch's int64 does.
 *
 * Every array argument is an address (torch.Tensor.data_ptr()) of a contiguous CPU tensor.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

#include "native_maths.h" /* splitmix64 */


/* draw(P, n, seeds, counter, mask, salt, as_uniform, out, new_counter): out[p, i] is word
 * counter[p] + i of agent p's stream (seeds[p] ^ salt), as int64 bits or as a uniform in
 * [0, 1) from its 53 high bits; new_counter[p] = counter[p] + n where mask[p] (uint8, or 0 for
 * every agent), counter[p] elsewhere. */
static PyObject *draw(PyObject *self, PyObject *args)
{
    Py_ssize_t P, n;
    unsigned long long seeds_p, counter_p, mask_p, out_p, new_p;
    long long salt;
    int as_uniform;
    if (!PyArg_ParseTuple(args, "nnKKKLiKK", &P, &n, &seeds_p, &counter_p, &mask_p, &salt,
                          &as_uniform, &out_p, &new_p))
        return NULL;
    const int64_t *seeds = (const int64_t *)(uintptr_t)seeds_p;
    const int64_t *counter = (const int64_t *)(uintptr_t)counter_p;
    const uint8_t *mask = (const uint8_t *)(uintptr_t)mask_p;
    int64_t *new_counter = (int64_t *)(uintptr_t)new_p;
    for (Py_ssize_t p = 0; p < P; p++) {
        uint64_t key = (uint64_t)seeds[p] ^ (uint64_t)salt;
        for (Py_ssize_t i = 0; i < n; i++) {
            uint64_t word = splitmix64(key + ((uint64_t)counter[p] + (uint64_t)i) * GOLDEN_GAMMA);
            if (as_uniform)
                ((double *)(uintptr_t)out_p)[p * n + i] = (double)(word >> 11) * 0x1.0p-53;
            else
                ((int64_t *)(uintptr_t)out_p)[p * n + i] = (int64_t)word;
        }
        new_counter[p] = (!mask || mask[p]) ? counter[p] + n : counter[p];
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"draw", draw, METH_VARARGS, "Words or uniforms of every agent's stream."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rng",
                                    "Compiled CounterRNG draws (see rng.py).", -1, methods};

PyMODINIT_FUNC PyInit__rng(void) { return PyModule_Create(&module); }
