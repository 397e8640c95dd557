/* The substep loop of impact_env.transport.physics.World below Python, and the two small per-step kernels
 * around it (action -> wrenches, state -> observation). See impact_env/transport/native.py for the design.
 *
 * Chipmunk is reached through the function pointers pymunk's own cffi module exposes
 * (ffi.addressof(lib, "cpSpaceStep"), ...), so nothing is linked against a file of another package and no
 * chipmunk header is needed: the seven prototypes below are checked against pymunk's cdef at run time.
 * Every operation is the one the Python paths do, in the same order, with the same libm functions:
 * compile with -ffp-contract=off (no fused multiply-add) and without gcc's sin/cos builtins (no fusion into
 * sincos), so that the results are the Python path's bit for bit.
 *
 * The GIL stays held: chipmunk calls pymunk's collision callbacks (cffi "extern Python" functions), which
 * take the GIL they already have, exactly as when Python calls lib.cpSpaceStep.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

typedef struct { double x, y; } cpVect; /* chipmunk's cpVect with cpFloat = double (checked at run time) */
typedef struct cpSpace cpSpace;
typedef struct cpBody cpBody;

typedef void (*space_step_fn)(cpSpace *, double);
typedef double (*body_double_fn)(cpBody *);
typedef cpVect (*body_vect_fn)(cpBody *);
typedef void (*set_force_fn)(cpBody *, cpVect);
typedef void (*set_torque_fn)(cpBody *, double);

/* ------------------------------------------------------------------------------------ buffers */

/* A C-contiguous writable or read-only buffer of n items of the given format ("d" or "f"). */
static int get_buffer(PyObject *obj, Py_buffer *view, const char *format, Py_ssize_t n, int writable,
                      const char *what) {
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    if (view->format == NULL || strcmp(view->format, format) != 0 || view->len != n * view->itemsize) {
        PyErr_Format(PyExc_ValueError, "%s must be a C-contiguous array of %zd items of format '%s'", what, n,
                     format);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------------------------ SubstepLoop */

typedef struct {
    PyObject_HEAD
    space_step_fn space_step;
    body_double_fn get_angle, get_angular_velocity;
    body_vect_fn get_position, get_velocity;
    set_force_fn set_force;
    set_torque_fn set_torque;
    cpSpace *space;
    cpBody **bodies; /* scenario order: robots first */
    Py_ssize_t n_bodies, n_robots;
    double dt;
    PyObject *owner;     /* the pymunk Space: keeps every pointer above alive */
    PyObject *separated; /* World._separated: a contact ended in the substep when it is not empty */
    Py_buffer wrench_view; /* World.wrench, (n_robots, 3) float64: body-frame Fx, Fy, torque */
    long long substeps_done;
} SubstepLoop;

static void *address_of(PyObject *seq, Py_ssize_t i) {
    PyObject *item = PySequence_GetItem(seq, i);
    if (item == NULL) return NULL;
    void *p = PyLong_AsVoidPtr(item);
    Py_DECREF(item);
    return p;
}

static int SubstepLoop_init(SubstepLoop *self, PyObject *args, PyObject *kwds) {
    PyObject *functions, *space_address, *body_addresses, *owner, *separated, *wrench;
    Py_ssize_t n_robots;
    double dt;
    static char *kwlist[] = {"functions", "space", "bodies", "n_robots", "dt", "owner", "separated", "wrench", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOndOO!O", kwlist, &functions, &space_address, &body_addresses,
                                     &n_robots, &dt, &owner, &PyList_Type, &separated, &wrench))
        return -1;
    if (self->bodies != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "SubstepLoop is initialised once");
        return -1;
    }
    if (!PySequence_Check(functions) || PySequence_Size(functions) != 7) {
        PyErr_SetString(PyExc_ValueError, "functions must be the addresses of the 7 chipmunk functions");
        return -1;
    }
    void *f[7];
    for (int i = 0; i < 7; i++) {
        f[i] = address_of(functions, i);
        if (f[i] == NULL) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a chipmunk function address is NULL");
            return -1;
        }
    }
    /* the order of impact_env.transport.native.CHIPMUNK_FUNCTIONS */
    self->space_step = (space_step_fn)f[0];
    self->get_angle = (body_double_fn)f[1];
    self->set_force = (set_force_fn)f[2];
    self->set_torque = (set_torque_fn)f[3];
    self->get_position = (body_vect_fn)f[4];
    self->get_velocity = (body_vect_fn)f[5];
    self->get_angular_velocity = (body_double_fn)f[6];
    self->space = (cpSpace *)PyLong_AsVoidPtr(space_address);
    if (self->space == NULL) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "space address is NULL");
        return -1;
    }
    Py_ssize_t n = PySequence_Size(body_addresses);
    if (n < 0) return -1;
    if (n_robots < 0 || n_robots > n) {
        PyErr_SetString(PyExc_ValueError, "n_robots must be in 0..len(bodies)");
        return -1;
    }
    self->bodies = PyMem_Calloc(n > 0 ? n : 1, sizeof(cpBody *));
    if (self->bodies == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        self->bodies[i] = (cpBody *)address_of(body_addresses, i);
        if (self->bodies[i] == NULL) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a body address is NULL");
            return -1;
        }
    }
    if (get_buffer(wrench, &self->wrench_view, "d", 3 * n_robots, 1, "wrench") < 0) return -1;
    self->n_bodies = n;
    self->n_robots = n_robots;
    self->dt = dt;
    Py_INCREF(owner);
    self->owner = owner;
    Py_INCREF(separated);
    self->separated = separated;
    return 0;
}

static void SubstepLoop_dealloc(SubstepLoop *self) {
    if (self->wrench_view.obj != NULL) PyBuffer_Release(&self->wrench_view);
    PyMem_Free(self->bodies);
    Py_XDECREF(self->owner);
    Py_XDECREF(self->separated);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int ready(SubstepLoop *self) {
    if (self->bodies == NULL || self->separated == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "SubstepLoop was not initialised");
        return 0;
    }
    return 1;
}

/* run(n): up to n substeps with the wrenches held; stops after a substep in which a contact ended (the
 * World closes it in Python, then calls again). Returns the number of substeps taken. */
static PyObject *SubstepLoop_run(SubstepLoop *self, PyObject *arg) {
    Py_ssize_t n = PyLong_AsSsize_t(arg);
    if (n == -1 && PyErr_Occurred()) return NULL;
    if (!ready(self)) return NULL;
    const double *w = (const double *)self->wrench_view.buf;
    Py_ssize_t done = 0;
    while (done < n) {
        for (Py_ssize_t r = 0; r < self->n_robots; r++) {
            cpBody *body = self->bodies[r];
            double a = self->get_angle(body);
            double c = cos(a), s = sin(a);
            double fx = w[3 * r], fy = w[3 * r + 1];
            cpVect force = {c * fx - s * fy, s * fx + c * fy};
            self->set_force(body, force);
            self->set_torque(body, w[3 * r + 2]);
        }
        self->space_step(self->space, self->dt);
        self->substeps_done++;
        done++;
        if (PyErr_Occurred()) return NULL;
        if (PyList_GET_SIZE(self->separated) > 0) break;
    }
    return PyLong_FromSsize_t(done);
}

/* read_state(out): per body (x, y, vx, vy, angle, angular velocity) into out, (n_bodies, 6) float64. */
static PyObject *SubstepLoop_read_state(SubstepLoop *self, PyObject *out) {
    Py_buffer view;
    if (!ready(self)) return NULL;
    if (get_buffer(out, &view, "d", 6 * self->n_bodies, 1, "out") < 0) return NULL;
    double *s = (double *)view.buf;
    for (Py_ssize_t i = 0; i < self->n_bodies; i++, s += 6) {
        cpBody *body = self->bodies[i];
        cpVect p = self->get_position(body), v = self->get_velocity(body);
        s[0] = p.x;
        s[1] = p.y;
        s[2] = v.x;
        s[3] = v.y;
        s[4] = self->get_angle(body);
        s[5] = self->get_angular_velocity(body);
    }
    PyBuffer_Release(&view);
    Py_RETURN_NONE;
}

static PyObject *SubstepLoop_get_done(SubstepLoop *self, void *closure) {
    return PyLong_FromLongLong(self->substeps_done);
}

static int SubstepLoop_set_done(SubstepLoop *self, PyObject *value, void *closure) {
    if (value == NULL) {
        PyErr_SetString(PyExc_AttributeError, "substeps_done cannot be deleted");
        return -1;
    }
    long long v = PyLong_AsLongLong(value);
    if (v == -1 && PyErr_Occurred()) return -1;
    self->substeps_done = v;
    return 0;
}

static PyMethodDef SubstepLoop_methods[] = {
    {"run", (PyCFunction)SubstepLoop_run, METH_O,
     "run(n) -> substeps taken: up to n substeps, stopping after one in which a contact ended."},
    {"read_state", (PyCFunction)SubstepLoop_read_state, METH_O,
     "read_state(out): (x, y, vx, vy, angle, angular velocity) of every body into out, (n_bodies, 6) float64."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef SubstepLoop_getset[] = {
    {"substeps_done", (getter)SubstepLoop_get_done, (setter)SubstepLoop_set_done,
     "substeps taken since the world was built (the World's clock)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject SubstepLoopType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "impact_env.transport._substeps.SubstepLoop",
    .tp_basicsize = sizeof(SubstepLoop),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "SubstepLoop(functions, space, bodies, n_robots, dt, owner, separated, wrench): the substeps of "
              "one World, below Python.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)SubstepLoop_init,
    .tp_dealloc = (destructor)SubstepLoop_dealloc,
    .tp_methods = SubstepLoop_methods,
    .tp_getset = SubstepLoop_getset,
};

/* ------------------------------------------------------------------------------------ scale_action */

/* scale_action(action, limits, out) -> bool: out[i] = clip(action[i], -1, 1) * limits[i] (float64 out and
 * limits, float32 or float64 action of the same length), as TransportCore.wrenches_from_action does. Returns
 * False and leaves out untouched if an action value is NaN or infinite (the caller raises its error). */
static PyObject *scale_action(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "scale_action(action, limits, out)");
        return NULL;
    }
    Py_buffer act, lim, out;
    if (PyObject_GetBuffer(args[0], &act, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    int is_float = act.format != NULL && strcmp(act.format, "f") == 0 && act.itemsize == 4;
    int is_double = act.format != NULL && strcmp(act.format, "d") == 0 && act.itemsize == 8;
    if (!is_float && !is_double) {
        PyBuffer_Release(&act);
        PyErr_SetString(PyExc_ValueError, "action must be float32 or float64");
        return NULL;
    }
    Py_ssize_t n = act.len / act.itemsize;
    if (get_buffer(args[1], &lim, "d", n, 0, "limits") < 0) {
        PyBuffer_Release(&act);
        return NULL;
    }
    if (get_buffer(args[2], &out, "d", n, 1, "out") < 0) {
        PyBuffer_Release(&act);
        PyBuffer_Release(&lim);
        return NULL;
    }
    int ok = 1;
    for (Py_ssize_t i = 0; i < n; i++) {
        double x = is_float ? (double)((const float *)act.buf)[i] : ((const double *)act.buf)[i];
        if (!isfinite(x)) {
            ok = 0;
            break;
        }
    }
    if (ok) {
        const double *l = (const double *)lim.buf;
        double *o = (double *)out.buf;
        for (Py_ssize_t i = 0; i < n; i++) {
            double x = is_float ? (double)((const float *)act.buf)[i] : ((const double *)act.buf)[i];
            o[i] = (x > 1.0 ? 1.0 : (x < -1.0 ? -1.0 : x)) * l[i];
        }
    }
    PyBuffer_Release(&act);
    PyBuffer_Release(&lim);
    PyBuffer_Release(&out);
    return PyBool_FromLong(ok);
}

/* ------------------------------------------------------------------------------------ Observer */

/* Observer(state, obs, low, high): observer(time_left) writes the central observation of state
 * ((n, 6) float64: x, y, vx, vy, heading, omega) into obs (7 n + 1 float32: x, y, vx, vy, cos, sin, omega per
 * body, then time_left), clipped to [low, high] as np.minimum then np.maximum do (NaN stays NaN). */
typedef struct {
    PyObject_HEAD
    Py_buffer state, obs, low, high;
    Py_ssize_t n_bodies;
} Observer;

static int Observer_init(Observer *self, PyObject *args, PyObject *kwds) {
    PyObject *state, *obs, *low, *high;
    static char *kwlist[] = {"state", "obs", "low", "high", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOO", kwlist, &state, &obs, &low, &high)) return -1;
    if (self->state.obj != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Observer is initialised once");
        return -1;
    }
    if (PyObject_GetBuffer(state, &self->state, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return -1;
    if (self->state.format == NULL || strcmp(self->state.format, "d") != 0 || self->state.len % (6 * 8) != 0) {
        PyErr_SetString(PyExc_ValueError, "state must be a C-contiguous (n, 6) float64 array");
        return -1;
    }
    self->n_bodies = self->state.len / (6 * 8);
    Py_ssize_t m = 7 * self->n_bodies + 1;
    if (get_buffer(obs, &self->obs, "f", m, 1, "obs") < 0) return -1;
    if (get_buffer(low, &self->low, "f", m, 0, "low") < 0) return -1;
    if (get_buffer(high, &self->high, "f", m, 0, "high") < 0) return -1;
    return 0;
}

static void Observer_dealloc(Observer *self) {
    Py_buffer *views[4] = {&self->state, &self->obs, &self->low, &self->high};
    for (int i = 0; i < 4; i++)
        if (views[i]->obj != NULL) PyBuffer_Release(views[i]);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Observer_call(Observer *self, PyObject *args, PyObject *kwds) {
    double time_left;
    if (kwds != NULL && PyDict_GET_SIZE(kwds) > 0) {
        PyErr_SetString(PyExc_TypeError, "Observer(time_left) takes no keywords");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "d", &time_left)) return NULL;
    if (self->obs.obj == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Observer was not initialised");
        return NULL;
    }
    const double *s = (const double *)self->state.buf;
    float *o = (float *)self->obs.buf;
    const float *lo = (const float *)self->low.buf, *hi = (const float *)self->high.buf;
    Py_ssize_t m = 7 * self->n_bodies + 1;
    for (Py_ssize_t i = 0; i < self->n_bodies; i++, s += 6) {
        float *b = o + 7 * i;
        b[0] = (float)s[0];
        b[1] = (float)s[1];
        b[2] = (float)s[2];
        b[3] = (float)s[3];
        b[4] = (float)cos(s[4]);
        b[5] = (float)sin(s[4]);
        b[6] = (float)s[5];
    }
    o[m - 1] = (float)time_left;
    for (Py_ssize_t j = 0; j < m; j++) {
        float v = o[j];
        if (v > hi[j]) v = hi[j]; /* np.minimum: NaN compares false and stays */
        if (v < lo[j]) v = lo[j];
        o[j] = v;
    }
    Py_INCREF(self->obs.obj);
    return self->obs.obj;
}

static PyTypeObject ObserverType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "impact_env.transport._substeps.Observer",
    .tp_basicsize = sizeof(Observer),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Observer(state, obs, low, high): observer(time_left) fills obs (and returns it).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Observer_init,
    .tp_dealloc = (destructor)Observer_dealloc,
    .tp_call = (ternaryfunc)Observer_call,
};

/* ------------------------------------------------------------------------------------ module */

static PyMethodDef module_methods[] = {
    {"scale_action", (PyCFunction)(void (*)(void))scale_action, METH_FASTCALL,
     "scale_action(action, limits, out) -> bool: clip to [-1, 1] and scale; False if a value is not finite."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_substeps", "The substep loop and per-step kernels of the transport world.", -1,
    module_methods,
};

PyMODINIT_FUNC PyInit__substeps(void) {
    if (PyType_Ready(&SubstepLoopType) < 0 || PyType_Ready(&ObserverType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module_def);
    if (m == NULL) return NULL;
    Py_INCREF(&SubstepLoopType);
    Py_INCREF(&ObserverType);
    if (PyModule_AddObject(m, "SubstepLoop", (PyObject *)&SubstepLoopType) < 0 ||
        PyModule_AddObject(m, "Observer", (PyObject *)&ObserverType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
