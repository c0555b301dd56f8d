/* FourierBasis's arguments pi * (c . x) on the CPU, compiled (see fourier.py).
 *
 * Why: forming the (order + 1)^dim arguments took a dozen small tensor operations (60-75 us for
 * one row) or several passes over [n, F] arrays; here it is one pass, and torch's cos follows
 * in place. The arithmetic is FourierBasis's, operation for operation: x_j c_j = x_j * (double)c_j,
 * summed left to right over the dims, then times pi, so the features are the same bits
 * (tests compare them). Compiled with -ffp-contract=off: no fused multiply-adds.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

/* The arguments of row i in FourierBasis's order: the partial sums (x_0 c_0 + x_1 c_1) + ... are
 * shared by all coefficient vectors with the same leading entries, last dimension fastest. */
static double *fourier_row(const double *t, long dim, long k, long j, double acc, double pi,
                           double *o)
{
    const double *tj = t + j * k;
    if (j == dim - 1) { /* the last dimension: k outputs in one tight loop */
        if (j == 0)
            for (long c = 0; c < k; c++) o[c] = pi * tj[c];
        else
            for (long c = 0; c < k; c++) o[c] = pi * (acc + tj[c]);
        return o + k;
    }
    for (long c = 0; c < k; c++)
        o = fourier_row(t, dim, k, j + 1, j == 0 ? tj[c] : acc + tj[c], pi, o);
    return o;
}

/* fourier_args(n, dim, order, x, x_stride0, x_stride1, pi, out): out[i, c] = pi * (c . x_i),
 * with c . x = ((x_0 c_0 + x_1 c_1) + ...) and x_j c_j = x_j * (double)c_j, as FourierBasis. */
static PyObject *fourier_args(PyObject *self, PyObject *args)
{
    Py_ssize_t n, dim, order, s0, s1;
    unsigned long long x_p, out_p;
    double pi;
    if (!PyArg_ParseTuple(args, "nnnKnndK", &n, &dim, &order, &x_p, &s0, &s1, &pi, &out_p))
        return NULL;
    if (dim < 1 || dim > 16 || order < 0 || order > 63) {
        PyErr_SetString(PyExc_ValueError, "fourier_args: need dim in 1..16 and order in 0..63");
        return NULL;
    }
    const double *x = (const double *)(uintptr_t)x_p;
    double *out = (double *)(uintptr_t)out_p;
    long k = order + 1, F = 1;
    for (long j = 0; j < dim; j++) F *= k;
    double t[16 * 64];
    for (Py_ssize_t i = 0; i < n; i++) {
        for (long j = 0; j < dim; j++)
            for (long c = 0; c < k; c++) t[j * k + c] = x[i * s0 + j * s1] * (double)c;
        fourier_row(t, dim, k, 0, 0.0, pi, out + i * F);
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fourier_args", fourier_args, METH_VARARGS, "pi * (c . x) for every coefficient vector."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_fourier",
                                    "Compiled Fourier-basis arguments (see fourier.py).", -1,
                                    methods};

PyMODINIT_FUNC PyInit__fourier(void) { return PyModule_Create(&module); }
