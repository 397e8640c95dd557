/* The kinematic substep loop of impact_env.tether.physics.TetherWorld below Python. See
 * impact_env/tether/native.py for the design.
 *
 * Chipmunk is reached through the function pointers pymunk's own cffi module exposes, as the transport world's
 * loop does (impact_env/transport/_substeps.c): three prototypes, checked against pymunk's cdef at run time.
 * Every operation is the one TetherWorld._step_kinematic_fast does, in the same order: compile with
 * -ffp-contract=off (no fused multiply-add), so that the results are the Python path's bit for bit. The one
 * function Python does not take from libm is math.hypot, which CPython computes by its own compensated
 * algorithm; py_hypot below does the same operations (a plain sqrt(x*x + y*y), or libm's hypot, differs from it
 * in the last bit now and then, and a trajectory carries such a bit on).
 *
 * A run stops, handing back to Python, before a substep that needs something only Python does (the wall test
 * of _slide_along_walls, or a distance of exactly 0, where Python raises ZeroDivisionError) and after a substep
 * whose tether checks or attachments are due. The GIL stays held: chipmunk calls pymunk's collision callbacks.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <float.h>
#include <math.h>
#include <stdint.h>

typedef struct { double x, y; } cpVect; /* chipmunk's cpVect with cpFloat = double (checked at run time) */
typedef struct cpSpace cpSpace;
typedef struct cpBody cpBody;

typedef void (*space_step_fn)(cpSpace *, double);
typedef cpVect (*body_vect_fn)(cpBody *);
typedef void (*set_vect_fn)(cpBody *, cpVect);

/* ------------------------------------------------------------------------------------ math.hypot */

/* A pair (hi, lo) whose exact sum is a result that one double cannot hold. */
typedef struct { double hi, lo; } Pair;

/* a + b exactly as hi + lo, for |a| >= |b| (Fast2Sum). */
static inline Pair add_exact(double a, double b) {
    double hi = a + b;
    return (Pair){hi, (a - hi) + b};
}

/* a * b exactly as hi + lo: Veltkamp's split of each factor into 26- and 27-bit halves, then Dekker's product.
 * CPython takes lo from fma(a, b, -hi) where the platform's fma is trusted; both are exact, so they agree. */
static inline Pair multiply_exact(double a, double b) {
    double ta = a * 134217729.0, tb = b * 134217729.0; /* 2**27 + 1 */
    double ah = ta - (ta - a), bh = tb - (tb - b);
    double al = a - ah, bl = b - bh;
    double p = ah * bh;
    double q = ah * bl + al * bh;
    double hi = p + q;
    return (Pair){hi, p - hi + q + al * bl};
}

/* Python's math.hypot(x, y) (CPython >= 3.11): both coordinates scaled by the power of two that brings the
 * larger into [0.5, 1), their squares summed exactly onto 1.0 with the rounding errors kept apart, the root
 * taken, then one Newton step against the exact residual; subnormal inputs are brought up by DBL_MIN first. */
static double py_hypot(double x, double y) {
    double a = fabs(x), b = fabs(y), big = 0.0;
    if (a > big) big = a;
    if (b > big) big = b;
    if (isinf(big)) return big;
    if (isnan(a) || isnan(b)) return NAN;
    if (big == 0.0) return big;
    int e;
    frexp(big, &e);
    if (e < -1023) return DBL_MIN * py_hypot(a / DBL_MIN, b / DBL_MIN);
    double scale = ldexp(1.0, -e), sum = 1.0, square_errors = 0.0, sum_errors = 0.0;
    double v[2] = {a * scale, b * scale};
    for (int i = 0; i < 2; i++) {
        Pair sq = multiply_exact(v[i], v[i]);
        Pair s = add_exact(sum, sq.hi);
        sum = s.hi;
        square_errors += sq.lo;
        sum_errors += s.lo;
    }
    double h = sqrt(sum - 1.0 + (square_errors + sum_errors));
    Pair sq = multiply_exact(-h, h);
    Pair s = add_exact(sum, sq.hi);
    sum = s.hi;
    square_errors += sq.lo;
    sum_errors += s.lo;
    double residual = sum - 1.0 + (square_errors + sum_errors);
    h += residual / (2.0 * h);
    return h / scale;
}

static PyObject *hypot_py(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "hypot(x, y) takes two floats");
        return NULL;
    }
    double x = PyFloat_AsDouble(args[0]), y = PyFloat_AsDouble(args[1]);
    if (PyErr_Occurred()) return NULL;
    return PyFloat_FromDouble(py_hypot(x, y));
}

/* ------------------------------------------------------------------------------------ KinematicLoop */

typedef struct {
    PyObject_HEAD
    space_step_fn space_step;
    body_vect_fn get_position;
    set_vect_fn set_velocity;
    cpSpace *space;
    cpBody *body;
    double dt, winch_N;
    PyObject *owner; /* the pymunk Space: keeps the pointers above alive */
    /* the plan: what the pulling tethers make of Eq. (5), set by set_plan when they change */
    Py_ssize_t n_reeling, n_held, capacity;
    double *reeling; /* (ax, ay) per reeling tether, robot order */
    double *speeds;  /* each reeling tether's w, read when shared_speed is 0 */
    double w;        /* the reeling tethers' common w when shared_speed is 1 */
    int shared_speed;
    double *held;    /* (ax, ay, held length) per held tether, robot order */
    int any_active;  /* a tether pulls or holds: the tether checks are due when the cargo leaves their budget */
} KinematicLoop;

static void *address_of(PyObject *seq, Py_ssize_t i) {
    PyObject *item = PySequence_GetItem(seq, i);
    if (item == NULL) return NULL;
    void *p = PyLong_AsVoidPtr(item);
    Py_DECREF(item);
    return p;
}

static int KinematicLoop_init(KinematicLoop *self, PyObject *args, PyObject *kwds) {
    PyObject *functions, *space_address, *body_address, *owner;
    double dt, winch_N;
    static char *kwlist[] = {"functions", "space", "body", "dt", "winch_N", "owner", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOddO", kwlist, &functions, &space_address, &body_address, &dt,
                                     &winch_N, &owner))
        return -1;
    if (self->owner != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "KinematicLoop is initialised once");
        return -1;
    }
    if (!PySequence_Check(functions) || PySequence_Size(functions) != 3) {
        PyErr_SetString(PyExc_ValueError, "functions must be the addresses of the 3 chipmunk functions");
        return -1;
    }
    void *f[3];
    for (int i = 0; i < 3; i++) {
        f[i] = address_of(functions, i);
        if (f[i] == NULL) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a chipmunk function address is NULL");
            return -1;
        }
    }
    /* the order of impact_env.tether.native.CHIPMUNK_FUNCTIONS */
    self->space_step = (space_step_fn)f[0];
    self->get_position = (body_vect_fn)f[1];
    self->set_velocity = (set_vect_fn)f[2];
    self->space = (cpSpace *)PyLong_AsVoidPtr(space_address);
    self->body = (cpBody *)PyLong_AsVoidPtr(body_address);
    if (self->space == NULL || self->body == NULL) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "space and body addresses must not be NULL");
        return -1;
    }
    if (!(dt > 0.0) || !isfinite(winch_N)) {
        PyErr_SetString(PyExc_ValueError, "dt must be > 0 and winch_N finite");
        return -1;
    }
    self->dt = dt;
    self->winch_N = winch_N;
    Py_INCREF(owner);
    self->owner = owner;
    return 0;
}

static void KinematicLoop_dealloc(KinematicLoop *self) {
    PyMem_Free(self->reeling);
    PyMem_Free(self->speeds);
    PyMem_Free(self->held);
    Py_XDECREF(self->owner);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Room for n tethers in each plan array. */
static int reserve(KinematicLoop *self, Py_ssize_t n) {
    if (n <= self->capacity) return 0;
    double *r = PyMem_Realloc(self->reeling, 2 * n * sizeof(double));
    if (r == NULL) goto nomemory;
    self->reeling = r;
    double *s = PyMem_Realloc(self->speeds, n * sizeof(double));
    if (s == NULL) goto nomemory;
    self->speeds = s;
    double *h = PyMem_Realloc(self->held, 3 * n * sizeof(double));
    if (h == NULL) goto nomemory;
    self->held = h;
    self->capacity = n;
    return 0;
nomemory:
    PyErr_NoMemory();
    return -1;
}

/* Read k floats of the tuple or list item into out; -1 (error set) if it is not such a sequence. */
static int read_floats(PyObject *item, double *out, Py_ssize_t k, const char *what) {
    PyObject *seq = PySequence_Fast(item, what);
    if (seq == NULL) return -1;
    if (PySequence_Fast_GET_SIZE(seq) != k) {
        PyErr_Format(PyExc_ValueError, "%s must hold %zd numbers", what, k);
        Py_DECREF(seq);
        return -1;
    }
    for (Py_ssize_t i = 0; i < k; i++) {
        out[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

/* set_plan(reeling, w, speeds, held, any_active): reeling a list of (ax, ay), speeds None (all reel at w) or a
 * list of one w per reeling tether, held a list of (ax, ay, length), any_active whether any tether pulls. */
static PyObject *KinematicLoop_set_plan(KinematicLoop *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "set_plan(reeling, w, speeds, held, any_active) takes 5 arguments");
        return NULL;
    }
    PyObject *reeling = args[0], *speeds = args[2], *held = args[3];
    if (!PyList_Check(reeling) || !PyList_Check(held) || (speeds != Py_None && !PyList_Check(speeds))) {
        PyErr_SetString(PyExc_TypeError, "set_plan: reeling and held must be lists, speeds a list or None");
        return NULL;
    }
    Py_ssize_t nr = PyList_GET_SIZE(reeling), nh = PyList_GET_SIZE(held);
    if (speeds != Py_None && PyList_GET_SIZE(speeds) != nr) {
        PyErr_SetString(PyExc_ValueError, "set_plan: one speed per reeling tether");
        return NULL;
    }
    double w = PyFloat_AsDouble(args[1]);
    if (w == -1.0 && PyErr_Occurred()) return NULL;
    int any_active = PyObject_IsTrue(args[4]);
    if (any_active < 0) return NULL;
    self->n_reeling = self->n_held = 0; /* an empty plan until this one is read in full */
    self->any_active = 0;
    if (reserve(self, nr > nh ? nr : nh) < 0) return NULL;
    for (Py_ssize_t i = 0; i < nr; i++) {
        if (read_floats(PyList_GET_ITEM(reeling, i), self->reeling + 2 * i, 2, "a reeling anchor") < 0) return NULL;
        if (speeds != Py_None) {
            self->speeds[i] = PyFloat_AsDouble(PyList_GET_ITEM(speeds, i));
            if (self->speeds[i] == -1.0 && PyErr_Occurred()) return NULL;
        }
    }
    for (Py_ssize_t i = 0; i < nh; i++)
        if (read_floats(PyList_GET_ITEM(held, i), self->held + 3 * i, 3, "a held tether") < 0) return NULL;
    self->n_reeling = nr;
    self->n_held = nh;
    self->w = w;
    self->shared_speed = speeds == Py_None;
    self->any_active = any_active;
    Py_RETURN_NONE;
}

/* Eq. (5) at (x, y), as physics.eq5_velocity: w times the sum of the unit vectors toward the reeling anchors (or
 * each tether's own w times its unit vector). 0, or -1 if the cargo is exactly at an anchor. */
static inline int eq5(const KinematicLoop *self, double x, double y, double *vx, double *vy) {
    double sx = 0.0, sy = 0.0;
    const double *a = self->reeling;
    for (Py_ssize_t i = 0; i < self->n_reeling; i++) {
        double dx = a[2 * i] - x, dy = a[2 * i + 1] - y;
        double d = py_hypot(dx, dy);
        if (d == 0.0) return -1;
        if (self->shared_speed) {
            sx += dx / d;
            sy += dy / d;
        } else {
            double wi = self->speeds[i];
            sx += wi * dx / d;
            sy += wi * dy / d;
        }
    }
    if (self->shared_speed) {
        *vx = self->w * sx;
        *vy = self->w * sy;
    } else {
        *vx = sx;
        *vy = sy;
    }
    return 0;
}

/* One classical Runge-Kutta step of Eq. (5) from (x, y), as physics._rk4_eq5 (and _rk4_one, _rk4_two, which
 * are the same operations written out). */
static inline int rk4(const KinematicLoop *self, double x, double y, double *nx, double *ny) {
    double dt = self->dt, h = 0.5 * dt, k1x, k1y, k2x, k2y, k3x, k3y, k4x, k4y;
    if (eq5(self, x, y, &k1x, &k1y) < 0) return -1;
    if (eq5(self, x + h * k1x, y + h * k1y, &k2x, &k2y) < 0) return -1;
    if (eq5(self, x + h * k2x, y + h * k2y, &k3x, &k3y) < 0) return -1;
    if (eq5(self, x + dt * k3x, y + dt * k3y, &k4x, &k4y) < 0) return -1;
    double sixth = dt / 6.0;
    *nx = x + sixth * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
    *ny = y + sixth * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
    return 0;
}

/* physics._keep_lengths: the velocity that lengthens no held tether. -1 if the cargo is exactly at an anchor. */
static inline int keep_lengths(const KinematicLoop *self, double x, double y, double *vx_, double *vy_) {
    double vx = *vx_, vy = *vy_, dt = self->dt;
    const double *t = self->held;
    for (int pass = 0; pass < 2; pass++) {
        for (Py_ssize_t i = 0; i < self->n_held; i++) {
            double ux = t[3 * i] - x, uy = t[3 * i + 1] - y;
            double d = py_hypot(ux, uy);
            if (d == 0.0) return -1;
            ux = ux / d;
            uy = uy / d;
            double toward = vx * ux + vy * uy;
            if (toward < 0.0) {
                vx = vx - toward * ux;
                vy = vy - toward * uy;
            }
        }
    }
    for (int pass = 0; pass < 2; pass++) {
        for (Py_ssize_t i = 0; i < self->n_held; i++) {
            double ax = t[3 * i], ay = t[3 * i + 1], length = t[3 * i + 2];
            double px = x + vx * dt - ax, py = y + vy * dt - ay;
            double d = py_hypot(px, py);
            if (d > length && length > 0.0) {
                double s = length / d;
                vx = (ax + px * s - x) / dt;
                vy = (ay + py * s - y) / dt;
            }
        }
    }
    *vx_ = vx;
    *vy_ = vy;
    return 0;
}

#define RUN_DONE 0       /* every substep asked for was taken */
#define RUN_PYTHON 1     /* stopped before a substep that Python must take (the wall test, a zero distance) */
#define RUN_CHECKS 2     /* stopped after a substep whose tether checks or attachments are due */

/* run(count, n, work, checked_x, checked_y, budget, wall_x, wall_y, wall_margin, next_ready) -> (n, work, stop):
 * up to count substeps of _step_kinematic_fast from the world's clock n (substeps taken) and winch work, with
 * the tether-check budget around (checked_x, checked_y), the wall margin around (wall_x, wall_y) (-inf: test
 * the walls every substep) and the next attachment's ready time (s). stop is RUN_DONE, RUN_PYTHON or
 * RUN_CHECKS. */
static PyObject *KinematicLoop_run(KinematicLoop *self, PyObject *const *args, Py_ssize_t nargs) {
    if (self->owner == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "KinematicLoop was not initialised");
        return NULL;
    }
    if (nargs != 10) {
        PyErr_SetString(PyExc_TypeError, "run takes 10 arguments (see its docstring)");
        return NULL;
    }
    Py_ssize_t count = PyLong_AsSsize_t(args[0]);
    if (count == -1 && PyErr_Occurred()) return NULL;
    long long n = PyLong_AsLongLong(args[1]);
    if (n == -1 && PyErr_Occurred()) return NULL;
    double v[8];
    for (int i = 0; i < 8; i++) {
        v[i] = PyFloat_AsDouble(args[2 + i]);
        if (v[i] == -1.0 && PyErr_Occurred()) return NULL;
    }
    double total = v[0], cx = v[1], cy = v[2], budget = v[3], sx = v[4], sy = v[5], margin = v[6];
    double next_ready = v[7], dt = self->dt, winch = self->winch_N;
    int stop = RUN_DONE;
    cpVect p = self->get_position(self->body);
    double x = p.x, y = p.y;
    for (Py_ssize_t k = 0; k < count; k++) {
        double vx = 0.0, vy = 0.0;
        if (self->n_reeling > 0) {
            if (!(py_hypot(x - sx, y - sy) < margin)) {
                stop = RUN_PYTHON;
                break;
            }
            double nx, ny;
            if (rk4(self, x, y, &nx, &ny) < 0) {
                stop = RUN_PYTHON;
                break;
            }
            vx = (nx - x) / dt;
            vy = (ny - y) / dt;
            if (self->n_held > 0 && keep_lengths(self, x, y, &vx, &vy) < 0) {
                stop = RUN_PYTHON;
                break;
            }
            /* Eq. (5)'s tension: every reeling winch at its limit, times the rate its tether shrinks */
            double work = 0.0;
            int at_anchor = 0;
            for (Py_ssize_t i = 0; i < self->n_reeling; i++) {
                double ux = self->reeling[2 * i] - x, uy = self->reeling[2 * i + 1] - y;
                double d = py_hypot(ux, uy);
                if (d == 0.0) {
                    at_anchor = 1;
                    break;
                }
                double rate = (vx * ux + vy * uy) / d;
                if (rate > 0.0) work += winch * rate * dt;
            }
            if (at_anchor) {
                stop = RUN_PYTHON;
                break;
            }
            total += work;
        }
        self->set_velocity(self->body, (cpVect){vx, vy});
        self->space_step(self->space, dt);
        n++;
        if (PyErr_Occurred()) return NULL;
        p = self->get_position(self->body);
        x = p.x;
        y = p.y;
        if ((self->any_active && !(py_hypot(x - cx, y - cy) < budget)) || next_ready <= (double)n * dt + 1e-9) {
            stop = RUN_CHECKS;
            break;
        }
    }
    return Py_BuildValue("(Ldi)", n, total, stop);
}

static PyMethodDef KinematicLoop_methods[] = {
    {"set_plan", (PyCFunction)(void (*)(void))KinematicLoop_set_plan, METH_FASTCALL,
     "set_plan(reeling, w, speeds, held, any_active): the pulling tethers, as _step_kinematic_fast's plan."},
    {"run", (PyCFunction)(void (*)(void))KinematicLoop_run, METH_FASTCALL,
     "run(count, n, work, checked_x, checked_y, budget, wall_x, wall_y, wall_margin, next_ready) -> (n, work, "
     "stop): up to count kinematic substeps (see the source)."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject KinematicLoopType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "impact_env.tether._substeps.KinematicLoop",
    .tp_basicsize = sizeof(KinematicLoop),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "KinematicLoop(functions, space, body, dt, winch_N, owner): the kinematic substeps of one "
              "TetherWorld, below Python.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)KinematicLoop_init,
    .tp_dealloc = (destructor)KinematicLoop_dealloc,
    .tp_methods = KinematicLoop_methods,
};

/* ------------------------------------------------------------------------------------ module */

static PyMethodDef module_methods[] = {
    {"hypot", (PyCFunction)(void (*)(void))hypot_py, METH_FASTCALL,
     "hypot(x, y): the loop's math.hypot (checked against Python's when the module is loaded)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_substeps", "The kinematic substep loop of the tether world.", -1, module_methods,
};

PyMODINIT_FUNC PyInit__substeps(void) {
    if (PyType_Ready(&KinematicLoopType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module_def);
    if (m == NULL) return NULL;
    Py_INCREF(&KinematicLoopType);
    if (PyModule_AddObject(m, "KinematicLoop", (PyObject *)&KinematicLoopType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
