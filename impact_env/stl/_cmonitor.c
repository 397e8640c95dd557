/* The online STL monitor of impact_env.stl.monitor, for the node classes the shipped tasks compile to, in C.
 * impact_env/stl/compiled.py builds the tables from OnlineMonitor's own node list and says which formulas fit.
 *
 * Each node mirrors the Python node of the same type (monitor.py: _Static, _Not, _Window, _Bool) step for step:
 * the same comparisons in the same order (Python's min/max keep the first of equal values, so ties and signed
 * zeros come out alike), the same IEEE operations (built with -ffp-contract=off), libm's sqrt, and Python's own
 * math.hypot called for the box distance (CPython computes hypot itself, not with libm). The temporal nodes are
 * those needed at one time only (lo == hi: every F/G and And/Or that no temporal operator nests), so each has
 * at most one accumulator, one tentative value and one buffered final per child.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

enum { T_STATIC = 0, T_NOT = 1, T_WINDOW = 2, T_BOOL = 3 };

/* columns of the node table (int64), in the order compiled.py writes them */
enum { C_TYPE, C_LO, C_HI, C_H, C_AND, C_A, C_B, C_CHILD, C_P0, C_NP, C_K0, C_NK, N_COLS };

typedef struct {
    int type;
    int64_t lo, hi, h, last;
    int is_and; /* STATIC, BOOL: min (And) or max (Or); WINDOW: 1 for G (min), 0 for F (max) */
    int64_t a, b;
    int64_t child;
    int64_t p0, np, k0, nk;
    /* state */
    double c;
    int has_out;
    double out;
    int has_tent;
    double tent; /* tentative value at the node's one needed time */
    int n_acc;
    double acc;
    int64_t acc_t0;
} Node;

typedef struct {
    int64_t region, row;
    int negate;
} Pred;

typedef struct {
    int64_t node;
    int buffered, has_buf;
    double buf;
} Kid;

typedef struct {
    int is_box;
    double box[4];
    int64_t n_edges;
    const double *edges; /* 8 per edge: vx, vy, ex, ey, nx, ny, off, ee (geometry.ConvexPolygon._edges_py) */
} Region;

typedef struct {
    PyObject_HEAD
    Node *nodes;
    int64_t n_nodes;
    Pred *preds;
    int64_t n_preds;
    Kid *kids;
    int64_t n_kids;
    Region *regions;
    int64_t n_regions;
    double *floats; /* the regions' numbers */
    int64_t *rows;     /* the rows checked for finite positions, in the order of the error messages */
    int64_t n_rows, max_row;
    PyObject *hypot; /* math.hypot */
    int64_t steps;
    int final;
    double value;
} Monitor;

static double INF_ = HUGE_VAL;

/* ------------------------------------------------------------------------------------ distances */

static int hypot_py(Monitor *self, double a, double b, double *out) {
    PyObject *args[2];
    args[0] = PyFloat_FromDouble(a);
    args[1] = PyFloat_FromDouble(b);
    if (args[0] == NULL || args[1] == NULL) {
        Py_XDECREF(args[0]);
        Py_XDECREF(args[1]);
        return -1;
    }
    PyObject *r = PyObject_Vectorcall(self->hypot, args, 2, NULL);
    Py_DECREF(args[0]);
    Py_DECREF(args[1]);
    if (r == NULL) return -1;
    *out = PyFloat_AsDouble(r);
    Py_DECREF(r);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* ConvexPolygon.signed_distance_xy, operation for operation */
static int signed_distance(Monitor *self, const Region *g, double x, double y, double *out) {
    if (g->is_box) {
        const double *box = g->box;
        double p = box[0] - x, q = x - box[1];
        double dx = q > p ? q : p; /* max(p, q) */
        p = box[2] - y;
        q = y - box[3];
        double dy = q > p ? q : p;
        if (dx <= 0.0 && dy <= 0.0) {
            *out = -(dx > dy ? dx : dy);
            return 0;
        }
        double h;
        if (hypot_py(self, dx > 0.0 ? dx : 0.0, dy > 0.0 ? dy : 0.0, &h) < 0) return -1;
        *out = -h;
        return 0;
    }
    double worst = -INF_;
    for (int64_t i = 0; i < g->n_edges; i++) {
        const double *e = g->edges + 8 * i;
        double d = e[4] * x + e[5] * y - e[6];
        if (d > worst) worst = d;
    }
    if (worst <= 0.0) {
        *out = -worst;
        return 0;
    }
    double best = INF_;
    for (int64_t i = 0; i < g->n_edges; i++) {
        const double *e = g->edges + 8 * i;
        double t = ((x - e[0]) * e[2] + (y - e[1]) * e[3]) / e[7];
        t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
        double dx = x - e[0] - t * e[2];
        double dy = y - e[1] - t * e[3];
        double d2 = dx * dx + dy * dy;
        if (d2 < best) best = d2;
    }
    *out = -sqrt(best);
    return 0;
}

/* ------------------------------------------------------------------------------------ nodes */

static int internal(const char *what) {
    PyErr_Format(PyExc_RuntimeError, "compiled STL monitor: %s (please report: the Python monitor handles this)",
                 what);
    return -1;
}

/* reduce: first value kept unless a later one is strictly smaller (min) / larger (max), as Python's min/max */
#define BETTER(is_min, v, best) ((is_min) ? ((v) < (best)) : ((v) > (best)))

static int step_static(Monitor *self, Node *n, int64_t k, const double *xy, int64_t stride) {
    double v = n->is_and ? INF_ : -INF_;
    for (int64_t i = 0; i < n->np; i++) {
        const Pred *p = &self->preds[n->p0 + i];
        const double *pos = xy + p->row * stride;
        double d;
        if (signed_distance(self, &self->regions[p->region], pos[0], pos[1], &d) < 0) return -1;
        if (p->negate) d = -d;
        if (BETTER(n->is_and, d, v)) v = d;
    }
    for (int64_t i = 0; i < n->nk; i++) {
        double c = self->nodes[self->kids[n->k0 + i].node].c;
        if (BETTER(n->is_and, c, v)) v = c;
    }
    n->c = v;
    n->has_out = k >= n->lo;
    n->out = v;
    return 0;
}

static int step_not(Monitor *self, Node *n) {
    const Node *ch = &self->nodes[n->child];
    n->c = -ch->c;
    n->has_out = ch->has_out;
    n->out = -ch->out;
    n->has_tent = 0;
    return 0;
}

static int step_window(Monitor *self, Node *n, int64_t k) {
    const Node *ch = &self->nodes[n->child];
    int is_min = n->is_and;
    if (k <= n->hi) n->c = ch->c;
    n->has_out = 0;
    if (ch->has_out) {
        double v = ch->out;
        int64_t tau = k - ch->h;
        if (n->lo <= tau - n->a && tau - n->a <= n->hi) {
            if (n->n_acc) return internal("a second accumulator");
            n->n_acc = 1;
            n->acc = v;
        }
        if (n->n_acc && BETTER(is_min, v, n->acc)) n->acc = v;
        if (tau - n->b == n->acc_t0) {
            if (!n->n_acc) return internal("a window without its accumulator");
            n->out = n->acc;
            n->has_out = 1;
            n->n_acc = 0;
            n->acc_t0 += 1;
        }
    }
    int64_t t0 = n->lo > k - n->h + 1 ? n->lo : k - n->h + 1;
    int64_t t1 = n->hi < k - 1 ? n->hi : k - 1;
    if (t0 > t1) {
        n->has_tent = 0;
        return 0;
    }
    int64_t t = t0, fin = k - ch->h;
    double best;
    if (t + n->a <= fin) {
        if (!n->n_acc || t != n->acc_t0) return internal("a tentative value without its accumulator");
        best = n->acc;
    } else {
        best = is_min ? INF_ : -INF_;
    }
    int64_t s = t + n->a > fin ? t + n->a : fin + 1;
    int64_t e = t + n->b < k ? t + n->b : k - 1;
    if (s <= e) return internal("a window over a child with tentative values");
    if (t + n->b >= k && BETTER(is_min, ch->c, best)) best = ch->c;
    n->tent = best;
    n->has_tent = 1;
    return 0;
}

static int step_bool(Monitor *self, Node *n, int64_t k) {
    int is_min = n->is_and;
    Kid *kids = self->kids + n->k0;
    if (k <= n->hi) {
        double v = 0.0;
        for (int64_t i = 0; i < n->nk; i++) {
            double c = self->nodes[kids[i].node].c;
            if (i == 0 || BETTER(is_min, c, v)) v = c;
        }
        n->c = v;
    }
    for (int64_t i = 0; i < n->nk; i++) {
        const Node *ch = &self->nodes[kids[i].node];
        if (kids[i].buffered && ch->has_out) {
            if (k - ch->h != n->lo || kids[i].has_buf) return internal("a second buffered final");
            kids[i].has_buf = 1;
            kids[i].buf = ch->out;
        }
    }
    int64_t tau = k - n->h;
    n->has_out = 0;
    if (tau >= n->lo) {
        double v = 0.0;
        for (int64_t i = 0; i < n->nk; i++) {
            const Node *ch = &self->nodes[kids[i].node];
            double x;
            if (kids[i].buffered) {
                if (!kids[i].has_buf || tau != n->lo) return internal("a final missing from its buffer");
                x = kids[i].buf;
                kids[i].has_buf = 0;
            } else {
                if (!ch->has_out) return internal("a final missing");
                x = ch->out;
            }
            if (i == 0 || BETTER(is_min, x, v)) v = x;
        }
        n->out = v;
        n->has_out = 1;
    }
    int64_t t0 = n->lo > tau + 1 ? n->lo : tau + 1;
    int64_t t1 = n->hi < k - 1 ? n->hi : k - 1;
    if (t0 > t1) {
        n->has_tent = 0;
        return 0;
    }
    int64_t t = t0;
    double v = 0.0;
    for (int64_t i = 0; i < n->nk; i++) {
        const Node *ch = &self->nodes[kids[i].node];
        double x;
        if (!kids[i].buffered || t > k - ch->h) {
            if (!ch->has_tent) return internal("a tentative value missing");
            x = ch->tent;
        } else {
            if (!kids[i].has_buf) return internal("a buffered final missing");
            x = kids[i].buf;
        }
        if (i == 0 || BETTER(is_min, x, v)) v = x;
    }
    n->tent = v;
    n->has_tent = 1;
    return 0;
}

/* ------------------------------------------------------------------------------------ Monitor */

/* a C-contiguous table of 8-byte items, cols per row: float64 ("d") or int64 (format "l" or "q") */
static int table(PyObject *obj, Py_buffer *view, const char *format, int64_t cols, const char *what) {
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return -1;
    const char *f = view->format;
    int same = f != NULL && (strcmp(f, format) == 0 || (format[0] == 'l' && strcmp(f, "q") == 0));
    if (!same || view->itemsize != 8 || (view->len / 8) % cols != 0) {
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous table of %d columns of 8-byte items", what,
                     (int)cols);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static void reset_state(Monitor *self) {
    for (int64_t i = 0; i < self->n_nodes; i++) {
        Node *n = &self->nodes[i];
        n->c = NAN;
        n->has_out = 0;
        n->out = 0.0;
        n->has_tent = 0;
        n->tent = 0.0;
        n->n_acc = 0;
        n->acc = 0.0;
        n->acc_t0 = n->lo;
    }
    for (int64_t i = 0; i < self->n_kids; i++) {
        self->kids[i].has_buf = 0;
        self->kids[i].buf = 0.0;
    }
    self->steps = 0;
    self->final = 0;
    self->value = NAN;
}

/* Monitor(nodes, preds, kids, regions, floats, rows, hypot): nodes (n, N_COLS) int64, children before parents,
 * the root last; preds (m, 3) int64 (region, row, negate); kids (q, 2) int64 (node, buffered); regions (r, 7)
 * int64 (is_box, offset into floats, number of edges); floats float64 (a box's 4 bounds or 8 numbers per edge);
 * rows int64 (the rows read, checked finite in this order); hypot = math.hypot. */
static int Monitor_init(Monitor *self, PyObject *args, PyObject *kwds) {
    PyObject *o_nodes, *o_preds, *o_kids, *o_regions, *o_floats, *o_rows, *hypot;
    if (!PyArg_ParseTuple(args, "OOOOOOO", &o_nodes, &o_preds, &o_kids, &o_regions, &o_floats, &o_rows, &hypot))
        return -1;
    if (self->nodes != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Monitor is initialised once");
        return -1;
    }
    if (!PyCallable_Check(hypot)) {
        PyErr_SetString(PyExc_TypeError, "hypot must be math.hypot");
        return -1;
    }
    Py_buffer vn, vp, vk, vr, vf, vrows;
    if (table(o_nodes, &vn, "l", N_COLS, "nodes") < 0) return -1;
    if (table(o_preds, &vp, "l", 3, "preds") < 0) goto fail_n;
    if (table(o_kids, &vk, "l", 2, "kids") < 0) goto fail_p;
    if (table(o_regions, &vr, "l", 3, "regions") < 0) goto fail_k;
    if (table(o_floats, &vf, "d", 1, "floats") < 0) goto fail_r;
    if (table(o_rows, &vrows, "l", 1, "rows") < 0) goto fail_f;

    self->n_nodes = vn.len / 8 / N_COLS;
    self->n_preds = vp.len / 8 / 3;
    self->n_kids = vk.len / 8 / 2;
    self->n_regions = vr.len / 8 / 3;
    self->n_rows = vrows.len / 8;
    int64_t n_floats = vf.len / 8;
    int ok = self->n_nodes > 0;
    self->nodes = PyMem_Calloc(self->n_nodes + 1, sizeof(Node));
    self->preds = PyMem_Calloc(self->n_preds + 1, sizeof(Pred));
    self->kids = PyMem_Calloc(self->n_kids + 1, sizeof(Kid));
    self->regions = PyMem_Calloc(self->n_regions + 1, sizeof(Region));
    self->floats = PyMem_Calloc(n_floats + 1, sizeof(double));
    self->rows = PyMem_Calloc(self->n_rows + 1, sizeof(int64_t));
    if (!self->nodes || !self->preds || !self->kids || !self->regions || !self->floats || !self->rows) {
        PyErr_NoMemory();
        goto fail_all;
    }
    memcpy(self->floats, vf.buf, n_floats * sizeof(double));
    const int64_t *t = (const int64_t *)vr.buf;
    for (int64_t i = 0; i < self->n_regions && ok; i++, t += 3) {
        Region *g = &self->regions[i];
        g->is_box = (int)t[0];
        g->n_edges = t[2];
        int64_t need = g->is_box ? 4 : 8 * g->n_edges;
        ok = t[1] >= 0 && t[1] + need <= n_floats && (g->is_box || g->n_edges > 0);
        if (!ok) break;
        if (g->is_box)
            memcpy(g->box, self->floats + t[1], 4 * sizeof(double));
        else
            g->edges = self->floats + t[1];
    }
    self->max_row = 0;
    t = (const int64_t *)vrows.buf;
    for (int64_t i = 0; i < self->n_rows && ok; i++) {
        self->rows[i] = t[i];
        ok = t[i] >= 0;
        if (t[i] > self->max_row) self->max_row = t[i];
    }
    t = (const int64_t *)vp.buf;
    for (int64_t i = 0; i < self->n_preds && ok; i++, t += 3) {
        self->preds[i].region = t[0];
        self->preds[i].row = t[1];
        self->preds[i].negate = (int)t[2];
        ok = t[0] >= 0 && t[0] < self->n_regions && t[1] >= 0 && t[1] <= self->max_row;
    }
    t = (const int64_t *)vk.buf;
    for (int64_t i = 0; i < self->n_kids && ok; i++, t += 2) {
        self->kids[i].node = t[0];
        self->kids[i].buffered = (int)t[1];
        ok = t[0] >= 0 && t[0] < self->n_nodes;
    }
    t = (const int64_t *)vn.buf;
    for (int64_t i = 0; i < self->n_nodes && ok; i++, t += N_COLS) {
        Node *n = &self->nodes[i];
        n->type = (int)t[C_TYPE];
        n->lo = t[C_LO];
        n->hi = t[C_HI];
        n->h = t[C_H];
        n->last = n->hi + n->h;
        n->is_and = (int)t[C_AND];
        n->a = t[C_A];
        n->b = t[C_B];
        n->child = t[C_CHILD];
        n->p0 = t[C_P0];
        n->np = t[C_NP];
        n->k0 = t[C_K0];
        n->nk = t[C_NK];
        ok = n->type >= T_STATIC && n->type <= T_BOOL && n->p0 >= 0 && n->np >= 0 && n->p0 + n->np <= self->n_preds &&
             n->k0 >= 0 && n->nk >= 0 && n->k0 + n->nk <= self->n_kids;
        for (int64_t j = 0; ok && j < n->nk; j++) ok = self->kids[n->k0 + j].node < i; /* children first */
        if (ok && (n->type == T_NOT || n->type == T_WINDOW)) ok = n->child >= 0 && n->child < i;
        if (ok && n->type != T_STATIC) ok = n->type == T_NOT || n->lo == n->hi; /* one needed time */
        if (ok && n->type == T_WINDOW) ok = self->nodes[n->child].h == 0 && n->b >= 1;
        if (ok && n->type == T_NOT) ok = self->nodes[n->child].h == 0;
        if (ok && n->type == T_BOOL) ok = n->nk >= 1;
    }
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "inconsistent monitor tables");
        goto fail_all;
    }
    Py_INCREF(hypot);
    self->hypot = hypot;
    reset_state(self);
    PyBuffer_Release(&vrows);
    PyBuffer_Release(&vf);
    PyBuffer_Release(&vr);
    PyBuffer_Release(&vk);
    PyBuffer_Release(&vp);
    PyBuffer_Release(&vn);
    return 0;
fail_all:
    PyMem_Free(self->nodes);
    PyMem_Free(self->preds);
    PyMem_Free(self->kids);
    PyMem_Free(self->regions);
    PyMem_Free(self->floats);
    PyMem_Free(self->rows);
    self->nodes = NULL;
    self->preds = NULL;
    self->kids = NULL;
    self->regions = NULL;
    self->floats = NULL;
    self->rows = NULL;
    PyBuffer_Release(&vrows);
fail_f:
    PyBuffer_Release(&vf);
fail_r:
    PyBuffer_Release(&vr);
fail_k:
    PyBuffer_Release(&vk);
fail_p:
    PyBuffer_Release(&vp);
fail_n:
    PyBuffer_Release(&vn);
    return -1;
}

static void Monitor_dealloc(Monitor *self) {
    PyMem_Free(self->nodes);
    PyMem_Free(self->preds);
    PyMem_Free(self->kids);
    PyMem_Free(self->regions);
    PyMem_Free(self->floats);
    PyMem_Free(self->rows);
    Py_XDECREF(self->hypot);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int ready(Monitor *self) {
    if (self->nodes == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Monitor was not initialised");
        return 0;
    }
    return 1;
}

/* update(xy, stride) -> value, or None (nothing changed) when a position read is not finite. xy: float64,
 * C-contiguous, body row r at xy[r * stride], xy[r * stride + 1]. */
static PyObject *Monitor_update(Monitor *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "update(xy, stride)");
        return NULL;
    }
    if (!ready(self)) return NULL;
    int64_t stride = PyLong_AsLongLong(args[1]);
    if (stride == -1 && PyErr_Occurred()) return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(args[0], &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    if (view.format == NULL || strcmp(view.format, "d") != 0 || stride < 2 ||
        (self->n_rows > 0 && view.len / 8 < self->max_row * stride + 2)) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "xy must be C-contiguous float64 holding every row the formula reads");
        return NULL;
    }
    const double *xy = (const double *)view.buf;
    for (int64_t i = 0; i < self->n_rows; i++) {
        const double *p = xy + self->rows[i] * stride;
        if (p[0] - p[0] != 0.0 || p[1] - p[1] != 0.0) { /* NaN or infinite, as OnlineMonitor tests it */
            PyBuffer_Release(&view);
            Py_RETURN_NONE;
        }
    }
    int64_t k = self->steps;
    if (!self->final) {
        for (int64_t i = 0; i < self->n_nodes; i++) {
            Node *n = &self->nodes[i];
            if (k > n->last) { /* finished: its last final must not be read again */
                n->has_out = 0;
                continue;
            }
            int rc;
            switch (n->type) {
            case T_STATIC: rc = step_static(self, n, k, xy, stride); break;
            case T_NOT: rc = step_not(self, n); break;
            case T_WINDOW: rc = step_window(self, n, k); break;
            default: rc = step_bool(self, n, k); break;
            }
            if (rc < 0) {
                PyBuffer_Release(&view);
                return NULL;
            }
        }
        Node *root = &self->nodes[self->n_nodes - 1];
        if (root->has_out) {
            self->final = 1;
            self->value = root->out;
        } else {
            self->value = root->has_tent ? root->tent : root->c;
        }
    }
    PyBuffer_Release(&view);
    self->steps = k + 1;
    return PyFloat_FromDouble(self->value);
}

static PyObject *Monitor_reset(Monitor *self, PyObject *unused) {
    if (!ready(self)) return NULL;
    reset_state(self);
    Py_RETURN_NONE;
}

/* the floats OnlineMonitor.live_state_size counts: tentative values, accumulators, buffered finals */
static PyObject *Monitor_live_state_size(Monitor *self, PyObject *unused) {
    if (!ready(self)) return NULL;
    int64_t n = 0;
    for (int64_t i = 0; i < self->n_nodes; i++) {
        const Node *nd = &self->nodes[i];
        n += nd->has_tent + (nd->type == T_WINDOW ? nd->n_acc : 0);
    }
    for (int64_t i = 0; i < self->n_kids; i++) n += self->kids[i].buffered && self->kids[i].has_buf;
    return PyLong_FromLongLong(n);
}

static PyObject *Monitor_get_value(Monitor *self, void *c) { return PyFloat_FromDouble(self->value); }
static PyObject *Monitor_get_steps(Monitor *self, void *c) { return PyLong_FromLongLong(self->steps); }
static PyObject *Monitor_get_final(Monitor *self, void *c) { return PyBool_FromLong(self->final); }

static PyMethodDef Monitor_methods[] = {
    {"update", (PyCFunction)(void (*)(void))Monitor_update, METH_FASTCALL,
     "update(xy, stride) -> robustness of the samples so far, or None if a position read is not finite"},
    {"reset", (PyCFunction)Monitor_reset, METH_NOARGS, "forget every sample"},
    {"live_state_size", (PyCFunction)Monitor_live_state_size, METH_NOARGS, "floats held between updates"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Monitor_getset[] = {
    {"value", (getter)Monitor_get_value, NULL, "robustness of the samples so far", NULL},
    {"steps", (getter)Monitor_get_steps, NULL, "samples seen since the last reset", NULL},
    {"is_final", (getter)Monitor_get_final, NULL, "True once later samples cannot change the value", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject MonitorType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "impact_env.stl._cmonitor.Monitor",
    .tp_basicsize = sizeof(Monitor),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Monitor(nodes, preds, kids, regions, floats, rows, hypot): see impact_env/stl/compiled.py",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Monitor_init,
    .tp_dealloc = (destructor)Monitor_dealloc,
    .tp_methods = Monitor_methods,
    .tp_getset = Monitor_getset,
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_cmonitor", "The online STL monitor of the shipped formula classes, in C.", -1, NULL,
};

PyMODINIT_FUNC PyInit__cmonitor(void) {
    if (0) {
        PyErr_SetString(PyExc_ImportError, "the compiled STL monitor needs a 64-bit int64_t");
        return NULL;
    }
    if (PyType_Ready(&MonitorType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module_def);
    if (m == NULL) return NULL;
    Py_INCREF(&MonitorType);
    if (PyModule_AddObject(m, "Monitor", (PyObject *)&MonitorType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
