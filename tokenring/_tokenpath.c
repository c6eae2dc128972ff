/*
 * The token path in C: the same visit as tokenring/node/tokenpath.py's PyTokenPath, step for step.
 *
 * TokenPath is the base type of tokenring.node.node_os.NodeOS. It keeps the ring state the visit
 * touches in C fields, exposed to Python under the attribute names the node uses (_epoch,
 * _accepted_crc, _last_sent_time, ...), so the watchdog, the acks and the user API read and
 * write them as before. The common visit (checks, copy, counter, seal, put) runs without
 * executing any Python code; every rare step calls the node's Python methods, exactly where
 * the Python path calls them. tests/ring/node/test_tokenpath.py compares the two paths byte for byte.
 *
 * Why C: a visit runs in a process whose caches the other nodes' visits have evicted, and the
 * interpreter's cost grows with every object and opcode it touches there (bench/RESULTS.md).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>

#include <errno.h>
#include <string.h>
#include <time.h>

static int ack_requested = 0x80; /* tokenring.contract.ring.ACK_REQUESTED, read at import */
static int epoch_mask = 0x7F;    /* tokenring.contract.ring.EPOCH_MASK, read at import */
static PyObject *epoch_order;    /* tokenring.contract.ring.epoch_order */

/* interned attribute and method names */
static PyObject *s_rejected_length, *s_rejected_crc, *s_rejected_marker, *s_rejected_did,
    *s_rejected_sid, *s_duplicate_passes, *s_successor, *s_visit, *s_acquire, *s_release,
    *s_send_ack, *s_answer_stale, *s_adopt_epoch, *s_include, *s_drop_outboxes,
    *s_activate_outboxes, *s_sweep_own_commands, *s_notify_visit, *s_send_failed, *s_sender,
    *s_replayed_passes;

/* The objects the node sets up, once: (Python attribute, C field). The struct, the garbage
   collector's traverse and clear, and the attribute table all come from this list. _defer hands
   a frame to the node's token thread (set by NodeOS.start). */
#define OBJECT_MEMBERS(X)                                                                         \
    X("stats", stats)                                                                             \
    X("membership", membership)                                                                   \
    X("transport", transport)                                                                     \
    X("system_handler", system_handler)                                                           \
    X("rx_fault", rx_fault)                                                                       \
    X("tx_fault", tx_fault)                                                                       \
    X("pacer", pacer)                                                                             \
    X("_token_lock", token_lock)                                                                  \
    X("_wake_lock", wake_lock)                                                                    \
    X("_live", live)                                                                              \
    X("_excluded", excluded)                                                                      \
    X("_senders", senders)                                                                        \
    X("_active", active)                                                                          \
    X("_pending_outboxes", pending_outboxes)                                                      \
    X("_outboxes", outboxes)                                                                      \
    X("_rounds_add", rounds_add)                                                                  \
    X("_handler_add", handler_add)                                                                \
    X("_send_add", send_add)                                                                      \
    X("_defer", defer)                                                                            \
    X("_accepted_frame", accepted_frame)
/* ... and the two whose type is checked where they are set (see TokenPath_getset) */
#define CHECKED_OBJECTS(X) X("_work", work) X("_const_bytes", const_bytes) X("_counters", counters)
#define ALL_OBJECTS(X) OBJECT_MEMBERS(X) CHECKED_OBJECTS(X)

/* The counters every visit adds to, as C integers: a Python int per counter would be read,
   allocated and written back per visit, in memory the other nodes' visits have evicted.
   tokenring.node.node_os.NodeStats reads and writes them through properties of the same names. */
#define HOT_COUNTERS(X) X(frames_received) X(frames_sent) X(visits) X(rounds) X(rounds_missed)

#define DECLARE_COUNTER(name) unsigned long long name;

typedef struct {
    PyObject_HEAD
    HOT_COUNTERS(DECLARE_COUNTER)
} Counters;

#define COUNTER_MEMBER(name) {#name, T_ULONGLONG, offsetof(Counters, name), 0, NULL},

static PyMemberDef Counters_members[] = {
    HOT_COUNTERS(COUNTER_MEMBER)
    {NULL},
};

static PyTypeObject CountersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "tokenring._tokenpath.Counters",
    .tp_doc = PyDoc_STR("The token path's per-visit counters as C integers (see NodeStats)."),
    .tp_basicsize = sizeof(Counters),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_members = Counters_members,
};

#define DECLARE_FIELD(name, field) PyObject *field;

typedef struct {
    PyObject_HEAD
    ALL_OBJECTS(DECLARE_FIELD)
    /* the layout, from protocol.yaml */
    int node_id, token_size, frame_size, o_sid, o_did, o_counter, o_issuer, o_epoch, o_origin;
    int const_lo;
    /* ring state */
    int epoch, origin, accepted_crc, accepted_sid, last_counter, retries, last_sent_did;
    int last_sent_crc, confirmed_did, regeneration_streak, visit_waiters, deferred_pending;
    double last_seen, last_visit, last_sent_time, confirmed_at, recovery_until, ack_interval;
    double hop, paced;
    unsigned long sends; /* every 16th send is timed */
    /* _token_lock's bound acquire and release, looked up once per lock, not once per visit */
    PyObject *lock_of_methods, *lock_acquire, *lock_release;
    char ack_pending, has_sent, ack_adaptive, ack_always, closing, leaving, departed;
    char system_busy;
} TokenPath;

#define COUNTERS(self) ((Counters *)(self)->counters)

/* ------------------------------------------------------------------------------------------ */

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts); /* time.perf_counter's clock on Linux */
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void sleep_for(double seconds)
{
    struct timespec ts;
    ts.tv_sec = (time_t)seconds;
    ts.tv_nsec = (long)((seconds - (double)ts.tv_sec) * 1e9);
    Py_BEGIN_ALLOW_THREADS
    while (clock_nanosleep(CLOCK_MONOTONIC, 0, &ts, &ts) == EINTR) {
    }
    Py_END_ALLOW_THREADS
}

/* CRC-16/ARC (poly 0x8005 reflected, init 0), table-driven */
static unsigned short crc_table[256];

static void crc_init(void)
{
    for (int i = 0; i < 256; i++) {
        unsigned short crc = (unsigned short)i;
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 1) ? (unsigned short)((crc >> 1) ^ 0xA001) : (unsigned short)(crc >> 1);
        crc_table[i] = crc;
    }
}

static unsigned int crc16_arc(const unsigned char *data, Py_ssize_t size)
{
    unsigned int crc = 0;
    for (Py_ssize_t i = 0; i < size; i++)
        crc = (crc >> 8) ^ crc_table[(crc ^ data[i]) & 0xFF];
    return crc;
}

static int stats_add(TokenPath *self, PyObject *name, long by)
{
    PyObject *value = PyObject_GetAttr(self->stats, name);
    if (value == NULL)
        return -1;
    long current = PyLong_AsLong(value);
    Py_DECREF(value);
    if (current == -1 && PyErr_Occurred())
        return -1;
    PyObject *updated = PyLong_FromLong(current + by);
    if (updated == NULL)
        return -1;
    int rc = PyObject_SetAttr(self->stats, name, updated);
    Py_DECREF(updated);
    return rc;
}

/* a hook's answer as C truth: 1, 0, or -1 with an exception set */
static int truth_of(PyObject *result)
{
    if (result == NULL)
        return -1;
    int truth = PyObject_IsTrue(result);
    Py_DECREF(result);
    return truth;
}

static int call_method_status(PyObject *self, PyObject *name, PyObject *a, PyObject *b,
                              PyObject *c)
{
    PyObject *result = PyObject_CallMethodObjArgs(self, name, a, b, c, NULL);
    if (result == NULL)
        return -1;
    Py_DECREF(result);
    return 0;
}

static int send_ack(TokenPath *self, int sid, int crc)
{
    PyObject *py_sid = PyLong_FromLong(sid), *py_crc = PyLong_FromLong(crc);
    int rc = (py_sid && py_crc)
        ? call_method_status((PyObject *)self, s_send_ack, py_sid, py_crc, NULL) : -1;
    Py_XDECREF(py_sid);
    Py_XDECREF(py_crc);
    return rc;
}

static int wake(TokenPath *self)
{
    if (self->wake_lock == NULL)
        return 0;
    PyObject *result = PyObject_CallMethodNoArgs(self->wake_lock, s_release);
    if (result != NULL) {
        Py_DECREF(result);
        return 0;
    }
    if (PyErr_ExceptionMatches(PyExc_RuntimeError)) { /* already awake */
        PyErr_Clear();
        return 0;
    }
    return -1;
}

/* ------------------------------------------------------------------------------------------ */
/* the send */

static int transmit(TokenPath *self, int did)
{
    if (self->closing)
        return 0;
    PyObject *py_did = PyLong_FromLong(did);
    if (py_did == NULL)
        return -1;
    if (self->tx_fault != NULL && self->tx_fault != Py_None) {
        int dropped = truth_of(PyObject_CallFunctionObjArgs(self->tx_fault, py_did, self->work, NULL));
        if (dropped != 0) {
            Py_DECREF(py_did);
            return dropped < 0 ? -1 : 0;
        }
    }
    PyObject *sender = PyDict_GetItemWithError(self->senders, py_did); /* borrowed */
    Py_XINCREF(sender);
    int ok = 0;
    if (sender == NULL && !PyErr_Occurred()) {
        sender = PyObject_CallMethodOneArg(self->transport, s_sender, py_did);
        if (sender != NULL && PyDict_SetItem(self->senders, py_did, sender) < 0)
            Py_CLEAR(sender);
    }
    if (sender != NULL) {
        if (self->sends++ & 15) {
            ok = truth_of(PyObject_CallOneArg(sender, self->work)) < 0 ? -1 : 0;
        } else { /* every 16th send is timed */
            double t0 = now();
            PyObject *result = PyObject_CallOneArg(sender, self->work);
            double took = now() - t0;
            if (result == NULL) {
                ok = -1;
            } else {
                Py_DECREF(result);
                PyObject *py_took = PyFloat_FromDouble(took);
                PyObject *added = py_took ? PyObject_CallOneArg(self->send_add, py_took) : NULL;
                Py_XDECREF(py_took);
                ok = added == NULL ? -1 : 0;
                Py_XDECREF(added);
            }
        }
        if (ok == 0)
            COUNTERS(self)->frames_sent++;
        Py_DECREF(sender);
    } else {
        ok = -1;
    }
    if (ok < 0 && PyErr_ExceptionMatches(PyExc_Exception)) {
        /* a backend error: counted and logged by the node, the watchdog retries the pass */
        PyObject *type, *value, *traceback;
        PyErr_Fetch(&type, &value, &traceback);
        PyErr_NormalizeException(&type, &value, &traceback);
        if (traceback != NULL)
            PyException_SetTraceback(value, traceback);
        ok = call_method_status((PyObject *)self, s_send_failed, py_did, value, NULL);
        Py_XDECREF(type);
        Py_XDECREF(value);
        Py_XDECREF(traceback);
    }
    Py_DECREF(py_did);
    return ok;
}

/* ------------------------------------------------------------------------------------------ */
/* the pass: seal the working token and send it to the successor (caller holds the token lock) */

static int forward(TokenPath *self, double t_in)
{
    unsigned char *work = (unsigned char *)PyByteArray_AS_STRING(self->work);
    PyObject *successor = PyObject_GetAttr(self->membership, s_successor);
    if (successor == NULL)
        return -1;
    long did = PyLong_AsLong(successor);
    Py_DECREF(successor);
    if (did == -1 && PyErr_Occurred())
        return -1;
    work[self->o_sid] = (unsigned char)self->node_id;
    work[self->o_did] = (unsigned char)did;
    int want_ack, arm_now;
    if (did == self->node_id)
        want_ack = arm_now = 0;
    else if (self->ack_adaptive) {
        /* a new link or a recovering ring: the watchdog arms the ack timer now; a link's
           periodic confirmation is checked on the watchdog's next wake (see tokenpath.py) */
        arm_now = did != self->confirmed_did || t_in < self->recovery_until;
        want_ack = arm_now || t_in - self->confirmed_at > self->ack_interval;
    } else
        want_ack = arm_now = self->ack_always;
    work[self->o_epoch] = (unsigned char)(want_ack ? self->epoch | ack_requested : self->epoch);
    work[self->o_origin] = (unsigned char)self->origin;
    unsigned int crc = crc16_arc(work, self->token_size);
    work[self->token_size] = (unsigned char)(crc & 0xFF);
    work[self->token_size + 1] = (unsigned char)(crc >> 8);
    double hop = self->hop;
    if (self->pacer != NULL && self->pacer != Py_None) { /* --profile: tokenring.node.pacing */
        PyObject *py_t = PyFloat_FromDouble(t_in);
        PyObject *paced = py_t ? PyObject_CallOneArg(self->pacer, py_t) : NULL;
        Py_XDECREF(py_t);
        if (paced == NULL)
            return -1;
        hop = PyFloat_AsDouble(paced);
        Py_DECREF(paced);
        if (hop == -1.0 && PyErr_Occurred())
            return -1;
    }
    if (did == self->node_id && hop < 0.001)
        hop = 0.001;
    if (hop != 0.0) {
        double delay = t_in + hop - now();
        if (delay > 0) {
            double slept_from = now();
            sleep_for(delay); /* emulated wire time; a lone node also waits 1 ms per pass */
            self->paced += now() - slept_from;
        }
    }
    if (did != self->last_sent_did || !self->ack_pending)
        self->retries = 0;
    else if (self->retries)
        self->retries += 1; /* still unanswered after a retry: a new token keeps the count */
    self->last_sent_did = (int)did;
    self->last_sent_crc = (int)crc;
    self->has_sent = 1;
    self->ack_pending = want_ack || (self->ack_pending && self->retries > 0);
    self->last_sent_time = now(); /* also ends the handler's time */
    if (transmit(self, (int)did) < 0)
        return -1;
    return arm_now ? wake(self) : 0;
}

/* ------------------------------------------------------------------------------------------ */
/* the visit */

static int visit_channels(TokenPath *self, double t_in)
{
    PyObject *active = self->active;
    if (active == NULL || !PyTuple_Check(active))
        return 0;
    Py_INCREF(active); /* the user API may swap the tuple while a channel runs Python code */
    PyObject *finished = NULL;
    int rc = 0;
    for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(active); i++) {
        PyObject *item = PyTuple_GET_ITEM(active, i);
        PyObject *result = PyObject_CallMethodOneArg(item, s_visit, self->work);
        if (result == NULL) {
            rc = -1;
            break;
        }
        int done = result == Py_True;
        Py_DECREF(result);
        if (done) {
            if (finished == NULL && (finished = PyList_New(0)) == NULL) {
                rc = -1;
                break;
            }
            if (PyList_Append(finished, item) < 0) {
                rc = -1;
                break;
            }
        }
    }
    Py_DECREF(active);
    if (rc == 0 && finished != NULL)
        rc = call_method_status((PyObject *)self, s_drop_outboxes, finished, NULL, NULL);
    Py_XDECREF(finished);
    if (rc < 0)
        return -1;
    if (self->pending_outboxes != NULL) {
        int pending = PyObject_IsTrue(self->pending_outboxes);
        if (pending < 0)
            return -1;
        if (pending && call_method_status((PyObject *)self, s_activate_outboxes, NULL, NULL, NULL) < 0)
            return -1;
    }
    if (t_in < self->recovery_until && self->outboxes != NULL) {
        int any = PyObject_IsTrue(self->outboxes);
        if (any < 0)
            return -1;
        if (any && call_method_status((PyObject *)self, s_sweep_own_commands, self->work, NULL, NULL) < 0)
            return -1;
    }
    return 0;
}

/* the rest of the visit, under the token lock: 1 when the pass is done and the bookkeeping
   after it should run, 0 when the visit ends here (leaving), -1 on error */
static int visit_locked(TokenPath *self, const unsigned char *frame, int sid, int crc, int flags,
                        double t_in, double *held, int *counter_out, int *wraps_out)
{
    unsigned char *work = (unsigned char *)PyByteArray_AS_STRING(self->work);
    memcpy(work, frame, (size_t)self->frame_size);
    self->last_seen = t_in;
    if (self->leaving) {
        if (forward(self, t_in) < 0)
            return -1;
        if ((flags & ack_requested) && send_ack(self, sid, crc) < 0)
            return -1;
        return 0;
    }
    int counter = work[self->o_counter];
    int system_active;
    if (self->system_handler == NULL || self->system_handler == Py_None)
        system_active = work[self->o_issuer] != 0;
    else if (work[self->o_issuer] || self->system_busy)
        system_active = truth_of(PyObject_CallOneArg(self->system_handler, self->work));
    else
        system_active = 0;
    if (system_active < 0)
        return -1;
    if (!system_active && visit_channels(self, t_in) < 0)
        return -1;
    work = (unsigned char *)PyByteArray_AS_STRING(self->work);
    int wraps = sid >= self->node_id; /* where the ring wraps the round is counted */
    if (wraps)
        work[self->o_counter] = (unsigned char)((counter + 1) & 0xFF);
    self->paced = 0.0;
    if (forward(self, t_in) < 0)
        return -1;
    *held = self->last_sent_time - t_in - self->paced;
    *counter_out = counter;
    *wraps_out = wraps;
    return 1;
}

static int bookkeeping(TokenPath *self, double t_in, int counter, int wraps)
{
    if (self->last_visit != 0.0) {
        PyObject *gap = PyFloat_FromDouble(t_in - self->last_visit);
        PyObject *added = gap ? PyObject_CallOneArg(self->rounds_add, gap) : NULL;
        Py_XDECREF(gap);
        if (added == NULL)
            return -1;
        Py_DECREF(added);
    }
    self->last_visit = t_in;
    if (self->regeneration_streak) { /* the token is back: the loss timer starts afresh */
        self->regeneration_streak = 0;
        if (wake(self) < 0)
            return -1;
    }
    int missed = (counter - self->last_counter) & 0xFF;
    if (missed > 1 && self->last_counter >= 0)
        COUNTERS(self)->rounds_missed += (unsigned long long)(missed - 1);
    self->last_counter = counter;
    COUNTERS(self)->visits++;
    if (wraps)
        COUNTERS(self)->rounds++;
    return 0;
}

/* _token_lock's bound acquire and release, fetched again only when the lock is another one */
static int lock_methods(TokenPath *self)
{
    if (self->lock_of_methods == self->token_lock && self->lock_acquire && self->lock_release)
        return 0;
    PyObject *acquire = PyObject_GetAttr(self->token_lock, s_acquire);
    PyObject *release = acquire ? PyObject_GetAttr(self->token_lock, s_release) : NULL;
    if (release == NULL) {
        Py_XDECREF(acquire);
        return -1;
    }
    Py_XSETREF(self->lock_acquire, acquire);
    Py_XSETREF(self->lock_release, release);
    Py_XSETREF(self->lock_of_methods, Py_NewRef(self->token_lock));
    return 0;
}

/* the node set up everything the visit uses without checks (NodeOS.__init__ does) */
static int ready(TokenPath *self)
{
    if (self->stats && self->membership && self->transport && self->work && self->token_lock &&
        self->live && self->excluded && self->senders && PyDict_Check(self->senders) &&
        self->const_bytes && self->counters && self->rounds_add && self->handler_add &&
        self->send_add &&
        PyByteArray_GET_SIZE(self->work) == self->frame_size && self->token_size > 0 &&
        self->token_size + 2 <= self->frame_size)
        return 1;
    PyErr_SetString(PyExc_RuntimeError, "the token path is used before the node set it up");
    return 0;
}

/* The pass last taken, byte for byte: a CRC-16 alone is no identity (two different frames from
   one sender share it once in 65536 passes, and the second was dropped as a "retry" — a lost
   token, about 20 an hour on the robot's ring, whose data changes every pass). */
static int same_as_accepted(TokenPath *self, const unsigned char *frame, Py_ssize_t len)
{
    PyObject *accepted = self->accepted_frame;
    return accepted != NULL && PyBytes_Check(accepted) && PyBytes_GET_SIZE(accepted) == len &&
           memcmp(PyBytes_AS_STRING(accepted), frame, (size_t)len) == 0;
}

static PyObject *visit_frame(TokenPath *self, PyObject *frame_obj)
{
    double t_in = now();
    if (!ready(self))
        return NULL;
    COUNTERS(self)->frames_received++;
    if (self->rx_fault != NULL && self->rx_fault != Py_None) {
        int dropped = truth_of(PyObject_CallOneArg(self->rx_fault, frame_obj));
        if (dropped != 0)
            return dropped < 0 ? NULL : Py_NewRef(Py_None);
    }
    if (self->departed)
        Py_RETURN_NONE;
    Py_buffer view;
    if (PyObject_GetBuffer(frame_obj, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    PyObject *rc = NULL;
    const unsigned char *frame = (const unsigned char *)view.buf;
    int size = self->token_size;
    PyObject *reject = NULL;
    if (view.len != self->frame_size)
        reject = s_rejected_length;
    else if (crc16_arc(frame, view.len) != 0) /* over a frame and its own CRC: zero */
        reject = s_rejected_crc;
    else if (memcmp(frame + self->const_lo, PyBytes_AS_STRING(self->const_bytes),
                    (size_t)PyBytes_GET_SIZE(self->const_bytes)) != 0)
        reject = s_rejected_marker;
    else if (frame[self->o_did] != self->node_id)
        reject = s_rejected_did;
    if (reject != NULL) {
        if (stats_add(self, reject, 1) == 0)
            rc = Py_NewRef(Py_None);
        goto done;
    }
    int sid = frame[self->o_sid];
    PyObject *py_sid = PyLong_FromLong(sid);
    int member = py_sid ? PySequence_Contains(self->live, py_sid) : -1;
    Py_XDECREF(py_sid);
    if (member <= 0) {
        if (member == 0 && stats_add(self, s_rejected_sid, 1) == 0)
            rc = Py_NewRef(Py_None);
        goto done;
    }
    int crc = frame[size] | (frame[size + 1] << 8);
    int flags = frame[self->o_epoch];
    if (crc == self->accepted_crc && sid == self->accepted_sid &&
        same_as_accepted(self, frame, view.len)) { /* a retry of a pass we took */
        if (stats_add(self, s_duplicate_passes, 1) == 0 &&
            (!(flags & ack_requested) || send_ack(self, sid, crc) == 0))
            rc = Py_NewRef(Py_None);
        goto done;
    }
    int epoch = flags & epoch_mask, origin = frame[self->o_origin];
    if (epoch != self->epoch || origin != self->origin) {
        PyObject *order = PyObject_CallFunction(epoch_order, "iiii", epoch, origin, self->epoch,
                                                self->origin);
        if (order == NULL)
            goto done;
        long newer = PyLong_AsLong(order);
        Py_DECREF(order);
        if (newer == -1 && PyErr_Occurred())
            goto done;
        PyObject *a = PyLong_FromLong(sid), *b = PyLong_FromLong(crc);
        int failed = !a || !b;
        if (!failed && newer < 0) {
            failed = call_method_status((PyObject *)self, s_answer_stale, a, b, NULL) < 0;
            Py_XDECREF(a);
            Py_XDECREF(b);
            if (!failed)
                rc = Py_NewRef(Py_None);
            goto done;
        }
        Py_XDECREF(a);
        Py_XDECREF(b);
        if (failed)
            goto done;
        PyObject *e = PyLong_FromLong(epoch), *o = PyLong_FromLong(origin);
        PyObject *t = PyFloat_FromDouble(t_in);
        failed = !e || !o || !t ||
                 call_method_status((PyObject *)self, s_adopt_epoch, e, o, t) < 0;
        Py_XDECREF(e);
        Py_XDECREF(o);
        Py_XDECREF(t);
        if (failed)
            goto done;
    }
    else if (self->last_counter >= 0) {
        /* within one epoch every node gets each round once: an older round, or the same round
           with other bytes, is a replayed pass or a second token */
        int back = (self->last_counter - frame[self->o_counter]) & 0xFF;
        if ((back > 0 && back < 128) || (back == 0 && !same_as_accepted(self, frame, view.len))) {
            if (stats_add(self, s_replayed_passes, 1) == 0)
                rc = Py_NewRef(Py_None);
            goto done;
        }
    }
    self->accepted_crc = crc;
    self->accepted_sid = sid;
    PyObject *accepted = PyBytes_CheckExact(frame_obj)
                             ? Py_NewRef(frame_obj)
                             : PyBytes_FromStringAndSize((const char *)frame, view.len);
    if (accepted == NULL)
        goto done;
    Py_XSETREF(self->accepted_frame, accepted);
    py_sid = PyLong_FromLong(sid);
    int excluded = py_sid ? PySequence_Contains(self->excluded, py_sid) : -1;
    if (excluded > 0)
        excluded = call_method_status((PyObject *)self, s_include, py_sid, Py_True, NULL);
    Py_XDECREF(py_sid);
    if (excluded < 0)
        goto done;

    if (lock_methods(self) < 0)
        goto done;
    PyObject *locked = PyObject_CallNoArgs(self->lock_acquire);
    if (locked == NULL)
        goto done;
    Py_DECREF(locked);
    double held = 0.0;
    int counter = 0, wraps = 0;
    int passed = visit_locked(self, frame, sid, crc, flags, t_in, &held, &counter, &wraps);
    if (passed > 0 && bookkeeping(self, t_in, counter, wraps) < 0)
        passed = -1;
    /* release whatever happened; an error raised above stays the one reported */
    PyObject *type = NULL, *value = NULL, *traceback = NULL;
    if (passed < 0)
        PyErr_Fetch(&type, &value, &traceback);
    PyObject *released = PyObject_CallNoArgs(self->lock_release);
    if (passed < 0) {
        Py_XDECREF(released);
        PyErr_Restore(type, value, traceback);
        goto done;
    }
    if (released == NULL)
        goto done;
    Py_DECREF(released);
    if (passed == 0) {
        rc = Py_NewRef(Py_None);
        goto done;
    }
    /* after the pass: the token must not wait for our ack */
    if ((flags & ack_requested) && send_ack(self, sid, crc) < 0)
        goto done;
    PyObject *py_held = PyFloat_FromDouble(held);
    PyObject *added = py_held ? PyObject_CallOneArg(self->handler_add, py_held) : NULL;
    Py_XDECREF(py_held);
    if (added == NULL)
        goto done;
    Py_DECREF(added);
    if (self->visit_waiters &&
        call_method_status((PyObject *)self, s_notify_visit, NULL, NULL, NULL) < 0)
        goto done;
    rc = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&view);
    return rc;
}

static int is_set(PyObject *hook)
{
    return hook != NULL && hook != Py_None;
}

/* The receiving thread's entry. A visit that may wait (emulated wire time, a pacer, a fault
   hook: delay, soft hang) goes to the node's token thread instead, and so does every frame
   while one is queued there, to keep their order: Zenoh's receiving thread must never wait,
   it also carries the node's acks, events and control queries. A lone node's pass to itself
   is handed over too: Zenoh delivers it inside the sender's own put, so visiting it here would
   recurse once per pass until the stack overflows. */
static int from_itself(TokenPath *self, PyObject *frame_obj)
{
    return PyBytes_Check(frame_obj) && PyBytes_GET_SIZE(frame_obj) > self->o_sid &&
           (unsigned char)PyBytes_AS_STRING(frame_obj)[self->o_sid] == self->node_id;
}

/* Zenoh calls the token's callback on its own receiving thread, which Python does not know:
   pyo3 makes a Python thread state for each call and deletes it after, and with it CPython 3.11
   maps and unmaps the state's 16 KB frame stack - an mmap/munmap pair, four page faults and a
   thread state's set-up per hop. One more PyGILState_Ensure on that thread, never released,
   keeps its state (and stack) for good; pyo3's own Ensure/Release then only take and drop the
   GIL. Threads Python started already have a state: for them this only raises its counter. */
static _Thread_local int thread_state_kept = 0;

static void keep_thread_state(void)
{
    if (!thread_state_kept) {
        (void)PyGILState_Ensure(); /* the GIL is held here, so this cannot block */
        thread_state_kept = 1;
    }
}

static PyObject *TokenPath_on_frame(TokenPath *self, PyObject *frame_obj)
{
    keep_thread_state();
    if (is_set(self->defer) && (self->deferred_pending > 0 || self->hop != 0.0 ||
                                from_itself(self, frame_obj) || is_set(self->pacer) ||
                                is_set(self->rx_fault) || is_set(self->tx_fault))) {
        self->deferred_pending += 1;
        PyObject *queued = PyObject_CallOneArg(self->defer, frame_obj);
        if (queued == NULL) {
            self->deferred_pending -= 1;
            return NULL;
        }
        Py_DECREF(queued);
        Py_RETURN_NONE;
    }
    return visit_frame(self, frame_obj);
}

static PyObject *TokenPath_visit_frame(TokenPath *self, PyObject *frame_obj)
{
    return visit_frame(self, frame_obj);
}

static PyObject *TokenPath_deferred_done(TokenPath *self, PyObject *Py_UNUSED(ignored))
{
    if (self->deferred_pending > 0)
        self->deferred_pending -= 1;
    Py_RETURN_NONE;
}

static PyObject *TokenPath_forward(TokenPath *self, PyObject *arg)
{
    if (!ready(self))
        return NULL;
    double t_in = PyFloat_AsDouble(arg);
    if (t_in == -1.0 && PyErr_Occurred())
        return NULL;
    if (forward(self, t_in) < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *TokenPath_transmit(TokenPath *self, PyObject *arg)
{
    if (!ready(self))
        return NULL;
    long did = PyLong_AsLong(arg);
    if (did == -1 && PyErr_Occurred())
        return NULL;
    if (transmit(self, (int)did) < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *TokenPath_wake(TokenPath *self, PyObject *Py_UNUSED(ignored))
{
    if (wake(self) < 0)
        return NULL;
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------------------------------ */
/* the type */

#define VISIT_FIELD(name, field) Py_VISIT(self->field);
#define CLEAR_FIELD(name, field) Py_CLEAR(self->field);

static int TokenPath_traverse(TokenPath *self, visitproc visit, void *arg)
{
    ALL_OBJECTS(VISIT_FIELD)
    Py_VISIT(self->lock_of_methods);
    Py_VISIT(self->lock_acquire);
    Py_VISIT(self->lock_release);
    return 0;
}

static int TokenPath_clear(TokenPath *self)
{
    ALL_OBJECTS(CLEAR_FIELD)
    Py_CLEAR(self->lock_of_methods);
    Py_CLEAR(self->lock_acquire);
    Py_CLEAR(self->lock_release);
    return 0;
}

static void TokenPath_dealloc(TokenPath *self)
{
    PyObject_GC_UnTrack(self);
    TokenPath_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* the attributes must hold what the visit expects: checked once where they are set, so the
   visit can use them without checks */
static int set_checked(TokenPath *self, PyObject *value, PyObject **slot, PyTypeObject *type,
                       const char *name)
{
    if (value == NULL) {
        PyErr_Format(PyExc_AttributeError, "%s cannot be deleted", name);
        return -1;
    }
    if (type != NULL && !PyObject_TypeCheck(value, type)) {
        PyErr_Format(PyExc_TypeError, "%s must be %s, not %s", name, type->tp_name,
                     Py_TYPE(value)->tp_name);
        return -1;
    }
    Py_XSETREF(*slot, Py_NewRef(value));
    return 0;
}

static PyObject *get_work(TokenPath *self, void *Py_UNUSED(closure))
{
    return Py_NewRef(self->work ? self->work : Py_None);
}

static int set_work(TokenPath *self, PyObject *value, void *Py_UNUSED(closure))
{
    if (value != NULL && PyByteArray_Check(value) && self->frame_size &&
        PyByteArray_GET_SIZE(value) != self->frame_size) {
        PyErr_Format(PyExc_ValueError, "_work must be %d bytes", self->frame_size);
        return -1;
    }
    return set_checked(self, value, &self->work, &PyByteArray_Type, "_work");
}

static PyObject *get_const_bytes(TokenPath *self, void *Py_UNUSED(closure))
{
    return Py_NewRef(self->const_bytes ? self->const_bytes : Py_None);
}

static int set_const_bytes(TokenPath *self, PyObject *value, void *Py_UNUSED(closure))
{
    return set_checked(self, value, &self->const_bytes, &PyBytes_Type, "_const_bytes");
}

static PyObject *get_counters(TokenPath *self, void *Py_UNUSED(closure))
{
    return Py_NewRef(self->counters ? self->counters : Py_None);
}

static int set_counters(TokenPath *self, PyObject *value, void *Py_UNUSED(closure))
{
    return set_checked(self, value, &self->counters, &CountersType, "_counters");
}

static PyGetSetDef TokenPath_getset[] = {
    {"_work", (getter)get_work, (setter)set_work, "the working token (a bytearray frame)", NULL},
    {"_const_bytes", (getter)get_const_bytes, (setter)set_const_bytes,
     "the header's constant markers", NULL},
    {"_counters", (getter)get_counters, (setter)set_counters,
     "the visit's counters (tokenring._tokenpath.Counters, NodeStats's)", NULL},
    {NULL},
};

#define OBJ(name, field) {name, T_OBJECT, offsetof(TokenPath, field), 0, NULL},
#define INT(name, field) {name, T_INT, offsetof(TokenPath, field), 0, NULL}
#define DBL(name, field) {name, T_DOUBLE, offsetof(TokenPath, field), 0, NULL}
#define BOOL(name, field) {name, T_BOOL, offsetof(TokenPath, field), 0, NULL}

static PyMemberDef TokenPath_members[] = {
    OBJECT_MEMBERS(OBJ)
    INT("node_id", node_id),
    INT("_token_size", token_size),
    INT("_frame_size", frame_size),
    INT("_o_sid", o_sid),
    INT("_o_did", o_did),
    INT("_o_counter", o_counter),
    INT("_o_issuer", o_issuer),
    INT("_o_epoch", o_epoch),
    INT("_o_origin", o_origin),
    INT("_const_lo", const_lo),
    INT("_epoch", epoch),
    INT("_origin", origin),
    INT("_accepted_crc", accepted_crc),
    INT("_accepted_sid", accepted_sid),
    INT("_last_counter", last_counter),
    INT("_retries", retries),
    INT("_last_sent_did", last_sent_did),
    INT("_last_sent_crc", last_sent_crc),
    INT("_confirmed_did", confirmed_did),
    INT("_regeneration_streak", regeneration_streak),
    INT("_visit_waiters", visit_waiters),
    INT("_deferred_pending", deferred_pending),
    DBL("_last_seen", last_seen),
    DBL("_last_visit", last_visit),
    DBL("_last_sent_time", last_sent_time),
    DBL("_confirmed_at", confirmed_at),
    DBL("_recovery_until", recovery_until),
    DBL("_ack_interval", ack_interval),
    DBL("_hop", hop),
    DBL("_paced", paced),
    BOOL("_ack_pending", ack_pending),
    BOOL("_has_sent", has_sent),
    BOOL("_ack_adaptive", ack_adaptive),
    BOOL("_ack_always", ack_always),
    BOOL("_closing", closing),
    BOOL("_leaving", leaving),
    BOOL("_departed", departed),
    BOOL("system_busy", system_busy),
    {NULL},
};

static PyMethodDef TokenPath_methods[] = {
    {"_on_frame", (PyCFunction)TokenPath_on_frame, METH_O,
     "A frame received: visited here, or handed to the token thread when the visit may wait."},
    {"_visit_frame", (PyCFunction)TokenPath_visit_frame, METH_O,
     "The token handler: one call per frame."},
    {"_deferred_done", (PyCFunction)TokenPath_deferred_done, METH_NOARGS,
     "The token thread finished a frame handed to it."},
    {"_forward", (PyCFunction)TokenPath_forward, METH_O,
     "Seal and pass the working token to the successor (caller holds the token lock)."},
    {"_transmit", (PyCFunction)TokenPath_transmit, METH_O,
     "Send the working buffer to a node as it is (a pass, a retry, a regeneration)."},
    {"_wake", (PyCFunction)TokenPath_wake, METH_NOARGS, "Wake the watchdog (idempotent)."},
    {NULL},
};

static PyTypeObject TokenPathType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "tokenring._tokenpath.TokenPath",
    .tp_doc = PyDoc_STR("The token path in C: the base of tokenring.node.node_os.NodeOS."),
    .tp_basicsize = sizeof(TokenPath),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .tp_new = PyType_GenericNew,
    .tp_dealloc = (destructor)TokenPath_dealloc,
    .tp_traverse = (traverseproc)TokenPath_traverse,
    .tp_clear = (inquiry)TokenPath_clear,
    .tp_members = TokenPath_members,
    .tp_getset = TokenPath_getset,
    .tp_methods = TokenPath_methods,
};

/* ------------------------------------------------------------------------------------------ */
/* the receiving entry: a Zenoh sample's payload, as bytes, to a frame handler */

static PyObject *s_payload, *s_to_bytes;

typedef struct {
    PyObject_HEAD
    PyObject *handler;
    vectorcallfunc vectorcall;
} PayloadCall;

static PyObject *PayloadCall_vectorcall(PayloadCall *self, PyObject *const *args, size_t nargsf,
                                        PyObject *kwnames)
{
    if (PyVectorcall_NARGS(nargsf) != 1 || kwnames != NULL) {
        PyErr_SetString(PyExc_TypeError, "PayloadCall takes one sample");
        return NULL;
    }
    PyObject *payload = PyObject_GetAttr(args[0], s_payload);
    if (payload == NULL)
        return NULL;
    PyObject *frame = PyObject_CallMethodNoArgs(payload, s_to_bytes);
    Py_DECREF(payload);
    if (frame == NULL)
        return NULL;
    PyObject *result = PyObject_CallOneArg(self->handler, frame);
    Py_DECREF(frame);
    return result;
}

static PyObject *PayloadCall_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    PyObject *handler;
    if (!PyArg_ParseTuple(args, "O:PayloadCall", &handler))
        return NULL;
    if (!PyCallable_Check(handler)) {
        PyErr_SetString(PyExc_TypeError, "PayloadCall needs a callable");
        return NULL;
    }
    PayloadCall *self = (PayloadCall *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->handler = Py_NewRef(handler);
    self->vectorcall = (vectorcallfunc)PayloadCall_vectorcall;
    return (PyObject *)self;
}

static int PayloadCall_traverse(PayloadCall *self, visitproc visit, void *arg)
{
    Py_VISIT(self->handler);
    return 0;
}

static int PayloadCall_clear(PayloadCall *self)
{
    Py_CLEAR(self->handler);
    return 0;
}

static void PayloadCall_dealloc(PayloadCall *self)
{
    PyObject_GC_UnTrack(self);
    PayloadCall_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyTypeObject PayloadCallType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "tokenring._tokenpath.PayloadCall",
    .tp_doc = PyDoc_STR("PayloadCall(handler)(sample) calls handler(sample.payload.to_bytes()): "
                        "the token's Zenoh callback without a Python frame per hop."),
    .tp_basicsize = sizeof(PayloadCall),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_new = PayloadCall_new,
    .tp_dealloc = (destructor)PayloadCall_dealloc,
    .tp_traverse = (traverseproc)PayloadCall_traverse,
    .tp_clear = (inquiry)PayloadCall_clear,
    .tp_call = PyVectorcall_Call,
    .tp_vectorcall_offset = offsetof(PayloadCall, vectorcall),
};

static struct PyModuleDef tokenpath_module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "tokenring._tokenpath",
    .m_doc = "The token path in C (see tokenring/node/tokenpath.py).",
    .m_size = -1,
};

static int intern(PyObject **slot, const char *name)
{
    *slot = PyUnicode_InternFromString(name);
    return *slot == NULL ? -1 : 0;
}

static int read_int(PyObject *module, const char *name, int *out)
{
    PyObject *value = PyObject_GetAttrString(module, name);
    if (value == NULL)
        return -1;
    long number = PyLong_AsLong(value);
    Py_DECREF(value);
    if (number == -1 && PyErr_Occurred())
        return -1;
    *out = (int)number;
    return 0;
}

PyMODINIT_FUNC PyInit__tokenpath(void)
{
    crc_init();
    struct {
        PyObject **slot;
        const char *name;
    } names[] = {
        {&s_rejected_length, "rejected_length"}, {&s_rejected_crc, "rejected_crc"},
        {&s_rejected_marker, "rejected_marker"}, {&s_rejected_did, "rejected_did"},
        {&s_rejected_sid, "rejected_sid"},       {&s_duplicate_passes, "duplicate_passes"},
        {&s_successor, "successor"},
        {&s_visit, "visit"},                     {&s_acquire, "acquire"},
        {&s_release, "release"},                 {&s_send_ack, "_send_ack"},
        {&s_answer_stale, "_answer_stale"},      {&s_adopt_epoch, "_adopt_epoch"},
        {&s_include, "_include"},                {&s_drop_outboxes, "_drop_outboxes"},
        {&s_activate_outboxes, "_activate_outboxes"},
        {&s_sweep_own_commands, "_sweep_own_commands"},
        {&s_notify_visit, "_notify_visit"},      {&s_send_failed, "_send_failed"},
        {&s_sender, "sender"},                   {&s_replayed_passes, "replayed_passes"},
        {&s_payload, "payload"},                 {&s_to_bytes, "to_bytes"},
    };
    for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); i++)
        if (intern(names[i].slot, names[i].name) < 0)
            return NULL;
    PyObject *ring = PyImport_ImportModule("tokenring.contract.ring");
    if (ring == NULL)
        return NULL;
    epoch_order = PyObject_GetAttrString(ring, "epoch_order");
    int failed = epoch_order == NULL || read_int(ring, "ACK_REQUESTED", &ack_requested) < 0 ||
                 read_int(ring, "EPOCH_MASK", &epoch_mask) < 0;
    Py_DECREF(ring);
    if (failed || PyType_Ready(&TokenPathType) < 0 || PyType_Ready(&PayloadCallType) < 0 ||
        PyType_Ready(&CountersType) < 0)
        return NULL;
    PyObject *module = PyModule_Create(&tokenpath_module);
    if (module == NULL)
        return NULL;
    if (PyModule_AddObjectRef(module, "TokenPath", (PyObject *)&TokenPathType) < 0 ||
        PyModule_AddObjectRef(module, "PayloadCall", (PyObject *)&PayloadCallType) < 0 ||
        PyModule_AddObjectRef(module, "Counters", (PyObject *)&CountersType) < 0) {
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
