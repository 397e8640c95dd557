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
#include <string.h>

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

/* ------------------------------------------------------------------------------------ actions */

/* The n action values of item as doubles into x: item a float32 or float64 C-contiguous buffer of shape (n,)
 * or, if rows > 0, (rows, n / rows). 0 on success, -1 if the item is not such a buffer (no Python error set). */
static int read_action(PyObject *item, double *x, Py_ssize_t n, Py_ssize_t rows) {
    Py_buffer v;
    if (PyObject_GetBuffer(item, &v, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        return -1;
    }
    int is_float = v.format != NULL && strcmp(v.format, "f") == 0 && v.itemsize == 4;
    int is_double = v.format != NULL && strcmp(v.format, "d") == 0 && v.itemsize == 8;
    int shaped = v.shape != NULL && ((v.ndim == 1 && v.shape[0] == n) ||
                                     (rows > 0 && v.ndim == 2 && v.shape[0] == rows && v.shape[1] * rows == n));
    int rc = -1;
    if ((is_float || is_double) && shaped && v.len == n * v.itemsize) {
        for (Py_ssize_t i = 0; i < n; i++)
            x[i] = is_float ? (double)((const float *)v.buf)[i] : ((const double *)v.buf)[i];
        rc = 0;
    }
    PyBuffer_Release(&v);
    return rc;
}

/* out[i] = clip(x[i], -1, 1) * limits[i], as TransportCore.wrenches_from_action does; False (out untouched) if
 * a value is NaN or infinite. */
static PyObject *scaled(const double *x, const double *limits, double *out, Py_ssize_t n) {
    for (Py_ssize_t i = 0; i < n; i++)
        if (!isfinite(x[i])) Py_RETURN_FALSE;
    for (Py_ssize_t i = 0; i < n; i++) out[i] = (x[i] > 1.0 ? 1.0 : (x[i] < -1.0 ? -1.0 : x[i])) * limits[i];
    Py_RETURN_TRUE;
}

#define MAX_ROBOTS 1024

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
    Py_buffer limits_view; /* the robots' (Fx, Fy, torque) limits, (n_robots, 3) float64 */
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
    PyObject *functions, *space_address, *body_addresses, *owner, *separated, *wrench, *limits;
    Py_ssize_t n_robots;
    double dt;
    static char *kwlist[] = {"functions", "space", "bodies", "n_robots", "dt", "owner", "separated", "wrench",
                             "limits", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOndOO!OO", kwlist, &functions, &space_address, &body_addresses,
                                     &n_robots, &dt, &owner, &PyList_Type, &separated, &wrench, &limits))
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
    if (n_robots < 0 || n_robots > n || n_robots > MAX_ROBOTS) {
        PyErr_SetString(PyExc_ValueError, "n_robots must be in 0..len(bodies) and at most 1024");
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
    if (get_buffer(limits, &self->limits_view, "d", 3 * n_robots, 0, "limits") < 0) return -1;
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
    if (self->limits_view.obj != NULL) PyBuffer_Release(&self->limits_view);
    PyMem_Free(self->bodies);
    Py_XDECREF(self->owner);
    Py_XDECREF(self->separated);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int ready(SubstepLoop *self) {
    if (self->bodies == NULL || self->separated == NULL || self->limits_view.obj == NULL) {
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

/* set_action(action) -> True, False or None: the wrench buffer = the scaled action. action: a float32 or
 * float64 C-contiguous array of shape (3 n_robots,) or (n_robots, 3), or a list or tuple of n_robots such
 * arrays of shape (3,). False (buffer untouched) if a value is NaN or infinite, None (untouched) if the action is
 * of another kind: the caller then takes its Python path, which raises the right error or reads the action. */
static PyObject *SubstepLoop_set_action(SubstepLoop *self, PyObject *action) {
    if (!ready(self)) return NULL;
    Py_ssize_t n = 3 * self->n_robots;
    double x[3 * MAX_ROBOTS];
    int read;
    if (PyList_CheckExact(action) || PyTuple_CheckExact(action)) {
        Py_ssize_t m = PySequence_Fast_GET_SIZE(action);
        PyObject **items = PySequence_Fast_ITEMS(action);
        read = m == self->n_robots;
        for (Py_ssize_t r = 0; read && r < m; r++) read = read_action(items[r], x + 3 * r, 3, 0) == 0;
    } else {
        read = read_action(action, x, n, self->n_robots) == 0;
    }
    if (!read) Py_RETURN_NONE;
    return scaled(x, (const double *)self->limits_view.buf, (double *)self->wrench_view.buf, n);
}

/* set_agent_actions(actions, agents, ndarray) -> True, False or None: set_action of the PettingZoo env's
 * actions, a dict from agent (robot i is agents[i]) to an ndarray (exactly) of shape (3,), float32 or
 * float64, a missing or None action being zeros. None (buffer untouched) if actions is not a dict, names
 * another agent or holds another kind of action: the caller takes its Python path. */
static PyObject *SubstepLoop_set_agent_actions(SubstepLoop *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3 || !PyTuple_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "set_agent_actions(actions, agents: tuple, ndarray)");
        return NULL;
    }
    if (!ready(self)) return NULL;
    PyObject *actions = args[0], *agents = args[1], *ndarray = args[2];
    if (!PyDict_CheckExact(actions) || PyTuple_GET_SIZE(agents) != self->n_robots) Py_RETURN_NONE;
    double x[3 * MAX_ROBOTS];
    Py_ssize_t found = 0;
    for (Py_ssize_t r = 0; r < self->n_robots; r++) {
        PyObject *item = PyDict_GetItemWithError(actions, PyTuple_GET_ITEM(agents, r));
        if (item == NULL && PyErr_Occurred()) return NULL;
        if (item != NULL) found++;
        if (item == NULL || item == Py_None) {
            x[3 * r] = x[3 * r + 1] = x[3 * r + 2] = 0.0;
        } else if ((PyObject *)Py_TYPE(item) != ndarray || read_action(item, x + 3 * r, 3, 0) < 0) {
            Py_RETURN_NONE;
        }
    }
    if (found != PyDict_GET_SIZE(actions)) Py_RETURN_NONE; /* an unknown agent: the Python path names it */
    return scaled(x, (const double *)self->limits_view.buf, (double *)self->wrench_view.buf, 3 * self->n_robots);
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
    {"set_action", (PyCFunction)SubstepLoop_set_action, METH_O,
     "set_action(action) -> True, False (not finite) or None (another kind): the wrench buffer = the scaled action."},
    {"set_agent_actions", (PyCFunction)(void (*)(void))SubstepLoop_set_agent_actions, METH_FASTCALL,
     "set_agent_actions(actions, agents, ndarray) -> True, False or None: set_action of PettingZoo's actions dict."},
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
    .tp_doc = "SubstepLoop(functions, space, bodies, n_robots, dt, owner, separated, wrench, limits): the "
              "substeps of one World, below Python, and the scaling of its actions.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)SubstepLoop_init,
    .tp_dealloc = (destructor)SubstepLoop_dealloc,
    .tp_methods = SubstepLoop_methods,
    .tp_getset = SubstepLoop_getset,
};

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

/* observer.agents(time_left, out, agents) -> dict: the central observation as observer(time_left), then each
 * robot's permutation of it (its own body's block first, then the other bodies in order, then the time left)
 * into the rows of out, (n_robots, 7 n + 1) float32; returns {agents[i]: out[i]} (row views of out). */
static PyObject *Observer_agents(Observer *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3 || !PyTuple_Check(args[2])) {
        PyErr_SetString(PyExc_TypeError, "agents(time_left, out, agents: tuple)");
        return NULL;
    }
    PyObject *targs = PyTuple_Pack(1, args[0]);
    if (targs == NULL) return NULL;
    PyObject *central = Observer_call(self, targs, NULL);
    Py_DECREF(targs);
    if (central == NULL) return NULL;
    Py_DECREF(central);
    Py_buffer view;
    Py_ssize_t m = 7 * self->n_bodies + 1;
    if (PyObject_GetBuffer(args[1], &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) return NULL;
    Py_ssize_t n_robots = view.len / (m * 4);
    if (view.format == NULL || strcmp(view.format, "f") != 0 || view.len != n_robots * m * 4 ||
        n_robots > self->n_bodies || PyTuple_GET_SIZE(args[2]) != n_robots) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "out must be a C-contiguous (n_robots, 7 n_bodies + 1) float32 array, "
                                          "agents a tuple of n_robots names");
        return NULL;
    }
    const float *o = (const float *)self->obs.buf;
    float *row = (float *)view.buf;
    for (Py_ssize_t r = 0; r < n_robots; r++, row += m) {
        memcpy(row, o + 7 * r, 7 * sizeof(float));
        float *dst = row + 7;
        for (Py_ssize_t j = 0; j < self->n_bodies; j++) {
            if (j == r) continue;
            memcpy(dst, o + 7 * j, 7 * sizeof(float));
            dst += 7;
        }
        row[m - 1] = o[m - 1];
    }
    PyBuffer_Release(&view);
    PyObject *result = PyDict_New();
    if (result == NULL) return NULL;
    for (Py_ssize_t r = 0; r < n_robots; r++) {
        PyObject *item = PySequence_GetItem(args[1], r);
        if (item == NULL || PyDict_SetItem(result, PyTuple_GET_ITEM(args[2], r), item) < 0) {
            Py_XDECREF(item);
            Py_DECREF(result);
            return NULL;
        }
        Py_DECREF(item);
    }
    return result;
}

static PyMethodDef Observer_methods[] = {
    {"agents", (PyCFunction)(void (*)(void))Observer_agents, METH_FASTCALL,
     "agents(time_left, out, agents) -> {agent: row of out}: each robot's observation into the rows of out."},
    {NULL, NULL, 0, NULL},
};

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
    .tp_methods = Observer_methods,
};

/* ------------------------------------------------------------------------------------ PettingZoo */

/* parallel_outputs(observer, time_left, out, names, agents, reward, terminated, truncated, info) ->
 * (observations, rewards, terminations, truncations, infos): what the PettingZoo env's step returns when every
 * agent lives. observations as observer.agents(time_left, out, names); rewards, terminations and truncations map
 * every agent to the same value; infos to a shallow copy of info each. */
static PyObject *parallel_outputs(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 9 || !PyObject_TypeCheck(args[0], &ObserverType) || !PyList_CheckExact(args[4]) ||
        !PyDict_Check(args[8])) {
        PyErr_SetString(PyExc_TypeError, "parallel_outputs(observer, time_left, out, names, agents: list, reward, "
                                         "terminated, truncated, info: dict)");
        return NULL;
    }
    PyObject *agents = args[4];
    PyObject *out[5] = {Observer_agents((Observer *)args[0], args + 1, 3), PyDict_New(), PyDict_New(), PyDict_New(),
                        PyDict_New()};
    if (!out[0] || !out[1] || !out[2] || !out[3] || !out[4]) goto fail;
    for (Py_ssize_t i = 0; i < PyList_GET_SIZE(agents); i++) {
        PyObject *a = PyList_GET_ITEM(agents, i);
        if (PyDict_SetItem(out[1], a, args[5]) < 0 || PyDict_SetItem(out[2], a, args[6]) < 0 ||
            PyDict_SetItem(out[3], a, args[7]) < 0)
            goto fail;
        PyObject *copy = PyDict_Copy(args[8]);
        if (copy == NULL) goto fail;
        int rc = PyDict_SetItem(out[4], a, copy);
        Py_DECREF(copy);
        if (rc < 0) goto fail;
    }
    PyObject *result = PyTuple_New(5);
    if (result == NULL) goto fail;
    for (int i = 0; i < 5; i++) PyTuple_SET_ITEM(result, i, out[i]); /* steals */
    return result;
fail:
    for (int i = 0; i < 5; i++) Py_XDECREF(out[i]);
    return NULL;
}

/* ------------------------------------------------------------------------------------ module */

static PyMethodDef module_methods[] = {
    {"parallel_outputs", (PyCFunction)(void (*)(void))parallel_outputs, METH_FASTCALL,
     "parallel_outputs(observer, time_left, out, names, agents, reward, terminated, truncated, info) -> the "
     "PettingZoo step's five per-agent dicts (see the source)."},
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
