/* The Pinball step of envs/pinball/physics.py, compiled, for a batch of balls: the env's
 * documented fast path (physics.NATIVE).
 *
 * Why it exists: a Python-float step cost 15-20 us a ball, which made the physics about two
 * thirds of a population trainer's step; this loop costs well under a microsecond a ball.
 *
 * Why it is bit-identical to the batched torch path: it performs the same
 * IEEE-double operations (+ - * / and one sqrt, all correctly rounded) in the same order, and
 * setup.py compiles it with -ffp-contract=off so that no multiply-add is fused. The tests step
 * random rollouts through both and compare every bit.
 *
 * Interface (CPython, METH_VARARGS): step(n, state, action, obs, reward, terminated, events,
 * board, edges, cell_start, cell_ids, clearance), every array argument an address (int, from
 * torch.Tensor.data_ptr(); 0 for an optional output):
 *   state       double[n][4]  x, y, xdot, ydot; advanced in place
 *   action      int64[n]      0..4
 *   obs         double[n][4]  optional: x, y, (xdot + 1) / 2, (ydot + 1) / 2 after the step
 *   reward      double[n]     -5 (thrust), -1 (none) or +10000 (goal)
 *   terminated  uint8[n]      1 where the ball reached the goal
 *   events      int64[n][4]   optional: single-edge, one-polygon, multi-polygon, out-of-bounds
 *   board       double[8]     r, target x, target y, target r^2, cell size, resolution,
 *                             number of edges, number of cells
 *   edges       double[E][6]  ax, ay, ex, ey, ex^2 + ey^2, polygon
 *   cell_start  int64[cells + 1], cell_ids int64[...]: the candidate edges of cell c are
 *                             cell_ids[cell_start[c] : cell_start[c + 1]]
 *   clearance   double[cells]
 * Returns the number of balls that reached the goal, or -(i + 1) if ball i had an action
 * outside 0..4 or a non-finite state (nothing is written past that ball).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

#define SUBSTEPS 20
#define DRAG 0.995
#define MAX_CANDIDATES 256

static const double IMPULSE[5][2] = {{1.0, 0.0}, {0.0, 1.0}, {-1.0, 0.0}, {0.0, -1.0}, {0.0, 0.0}};
static double COS2_APPROACH; /* cos(pi / 1.99)^2, computed by Python's math at import */
static const double RR_MARGIN = (1.0 + 1e-9) * (1.0 + 1e-9);

typedef struct {
    double r, tx, ty, tr2, h;
    long g, n_edges, n_cells;
    const double *edges;
    const int64_t *cell_start, *cell_ids;
    const double *clearance;
} Board;

static long cell_of(const Board *b, double x, double y)
{
    /* min(max(floor(x / h) + 1, 0), g - 1), clamped as doubles so that no huge value overflows */
    double i = floor(x / b->h) + 1.0, j = floor(y / b->h) + 1.0, top = (double)(b->g - 1);
    i = i < 0.0 ? 0.0 : (i > top ? top : i);
    j = j < 0.0 ? 0.0 : (j > top ? top : j);
    return (long)j * b->g + (long)i;
}

/* Substeps 0..19 near the candidate edges; returns 1 at the goal (physics.py's substeps). */
static int substeps(const Board *b, double *px, double *py, double *pvx, double *pvy,
                    const double **cand, int n_cand, int64_t *events)
{
    double x = *px, y = *py, vx = *pvx, vy = *pvy;
    const double r = b->r, r2 = r * r;
    for (int j = 0; j < SUBSTEPS; j++) {
        x += vx * r / SUBSTEPS;
        y += vy * r / SUBSTEPS;
        int n_hit = 0, one_polygon = 1;
        const double *first = NULL;
        double vv = vx * vx + vy * vy;
        for (int k = 0; k < n_cand; k++) {
            const double *e = cand[k];
            double t = ((x - e[0]) * e[2] + (y - e[1]) * e[3]) / e[4];
            t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
            double dx = x - (e[0] + e[2] * t);
            double dy = y - (e[1] + e[3] * t);
            double dist2 = dx * dx + dy * dy;
            if (dist2 <= r2) {
                double toward = -(dx * vx + dy * vy);
                if (toward >= 0.0 || toward * toward <= COS2_APPROACH * dist2 * vv) {
                    if (n_hit == 0)
                        first = e;
                    else if (e[5] != first[5])
                        one_polygon = 0;
                    n_hit++;
                }
            }
        }
        if (n_hit) {
            if (n_hit == 1) {
                double scale = 2.0 * (vx * first[2] + vy * first[3]) / first[4];
                double nvx = scale * first[2] - vx, nvy = scale * first[3] - vy;
                vx = nvx;
                vy = nvy;
                if (events) events[0]++;
            } else {
                vx = -vx;
                vy = -vy;
                if (events) events[one_polygon ? 1 : 2]++;
            }
            if (one_polygon && j == SUBSTEPS - 1) {
                x += vx * r / SUBSTEPS;
                y += vy * r / SUBSTEPS;
            }
        }
        double gx = x - b->tx, gy = y - b->ty;
        if (gx * gx + gy * gy < b->tr2) {
            *px = x; *py = y; *pvx = vx; *pvy = vy;
            return 1;
        }
    }
    *px = x; *py = y; *pvx = vx; *pvy = vy;
    return 0;
}

/* One step of one ball (physics.py's step, one row); returns 1 at the goal. */
static int step_one(const Board *b, double *s, int64_t action, int64_t *events)
{
    double x = s[0], y = s[1];
    double vx = s[2] + IMPULSE[action][0] / 5.0, vy = s[3] + IMPULSE[action][1] / 5.0;
    vx = vx > -1.0 ? vx : -1.0;  /* min(max(v, -1), 1), as Python evaluates it */
    vx = vx < 1.0 ? vx : 1.0;
    vy = vy > -1.0 ? vy : -1.0;
    vy = vy < 1.0 ? vy : 1.0;
    const double r = b->r;
    long cell = cell_of(b, x, y);
    double vv = vx * vx + vy * vy;
    double c = b->clearance[cell] - 1e-12;
    if (c > 0.0 && c * c > vv * RR_MARGIN * (r * r)) {
        double dx = vx * r / SUBSTEPS, dy = vy * r / SUBSTEPS;
        for (int j = 0; j < SUBSTEPS; j++) {
            x += dx;
            y += dy;
        }
        s[0] = x; s[1] = y; s[2] = vx * DRAG; s[3] = vy * DRAG;
        return 0;
    }
    /* The candidate edges this step can reach: a ball travels at most 21 |v| r / 20. */
    double reach = r + 21.0 * sqrt(vv) * r / SUBSTEPS + 1e-9, reach2 = reach * reach;
    const double *cand[MAX_CANDIDATES];
    int n_cand = 0;
    for (int64_t k = b->cell_start[cell]; k < b->cell_start[cell + 1]; k++) {
        const double *e = b->edges + 6 * b->cell_ids[k];
        double t = ((x - e[0]) * e[2] + (y - e[1]) * e[3]) / e[4];
        t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
        double dx = x - (e[0] + e[2] * t), dy = y - (e[1] + e[3] * t);
        if (dx * dx + dy * dy <= reach2 && n_cand < MAX_CANDIDATES) cand[n_cand++] = e;
    }
    if (substeps(b, &x, &y, &vx, &vy, cand, n_cand, events)) {
        s[0] = x; s[1] = y; s[2] = vx; s[3] = vy;
        return 1;
    }
    vx *= DRAG;
    vy *= DRAG;
    int moved = 0;
    if (x > 1.0) { x = 0.95; moved = 1; }
    else if (x < 0.0) { x = 0.05; moved = 1; }
    if (y > 1.0) { y = 0.95; moved = 1; }
    else if (y < 0.0) { y = 0.05; moved = 1; }
    if (moved) {
        vx = 0.0;
        vy = 0.0;
        if (events) events[3]++;
    }
    s[0] = x; s[1] = y; s[2] = vx; s[3] = vy;
    return 0;
}

static PyObject *native_step(PyObject *self, PyObject *args)
{
    Py_ssize_t n;
    unsigned long long state_p, action_p, obs_p, reward_p, term_p, events_p, board_p, edges_p,
        start_p, ids_p, clear_p;
    if (!PyArg_ParseTuple(args, "nKKKKKKKKKKK", &n, &state_p, &action_p, &obs_p, &reward_p,
                          &term_p, &events_p, &board_p, &edges_p, &start_p, &ids_p, &clear_p))
        return NULL;
    const double *bp = (const double *)(uintptr_t)board_p;
    Board b = {bp[0], bp[1], bp[2], bp[3], bp[4], (long)bp[5], (long)bp[6], (long)bp[7],
               (const double *)(uintptr_t)edges_p, (const int64_t *)(uintptr_t)start_p,
               (const int64_t *)(uintptr_t)ids_p, (const double *)(uintptr_t)clear_p};
    double *state = (double *)(uintptr_t)state_p, *obs = (double *)(uintptr_t)obs_p;
    double *reward = (double *)(uintptr_t)reward_p;
    const int64_t *action = (const int64_t *)(uintptr_t)action_p;
    uint8_t *terminated = (uint8_t *)(uintptr_t)term_p;
    int64_t *events = (int64_t *)(uintptr_t)events_p;
    long n_term = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        double *s = state + 4 * i;
        int64_t a = action[i];
        if (a < 0 || a > 4 || !isfinite(s[0]) || !isfinite(s[1]) || !isfinite(s[2]) ||
            !isfinite(s[3]))
            return PyLong_FromSsize_t(-(i + 1));
        int64_t *ev = NULL;
        if (events) {
            ev = events + 4 * i;
            ev[0] = ev[1] = ev[2] = ev[3] = 0;
        }
        int term = step_one(&b, s, a, ev);
        terminated[i] = (uint8_t)term;
        reward[i] = term ? 10000.0 : (a == 4 ? -1.0 : -5.0);
        n_term += term;
        if (obs) {
            double *o = obs + 4 * i;
            o[0] = s[0];
            o[1] = s[1];
            o[2] = (s[2] + 1.0) / 2.0;
            o[3] = (s[3] + 1.0) / 2.0;
        }
    }
    return PyLong_FromLong(n_term);
}

static PyObject *native_set_cos2(PyObject *self, PyObject *arg)
{
    COS2_APPROACH = PyFloat_AsDouble(arg);
    if (PyErr_Occurred()) return NULL;
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"step", native_step, METH_VARARGS, "Step n balls in place (see the file's header)."},
    {"set_cos2_approach", native_set_cos2, METH_O, "Set cos(pi / 1.99)^2 as Python computes it."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_native",
                                    "Compiled Pinball step (see native.py).", -1, methods};

PyMODINIT_FUNC PyInit__native(void) { return PyModule_Create(&module); }
