/* The message codec's fast path, in C: the same frames as emos/msgs/codec.py, byte for byte.
 *
 * Why it exists: encoding and decoding a small message costs 1-2 us in a warm Python loop, but
 * a topic's reader runs it straight after a wake-up, with cold caches, where the same Python
 * code (a dozen C calls into msgpack, struct and numpy, each through the interpreter) costs
 * 10-20 us: most of what EMOS adds to an 8 B message over Zenoh (docs/benchmarks-history.md, "A codec
 * in C"). One C call that walks the message's fields touches far less code.
 *
 * It is a fast path, never the only path. Each function either returns exactly what the Python
 * codec returns, or gives up and the Python codec runs instead: any value of a type it does not
 * write, any byte it does not expect, any frame that would not decode. So every error a user
 * sees comes from the Python codec, worded as before, and this file never has to decide whether
 * bytes from another process are valid: it only has to never read outside them, and to give up
 * (tests/runtime/test_ccodec.py compares both codecs on every message type and on mutated and
 * random frames).
 *
 * Frame layout (codec.py): u32 meta_len | meta (msgpack) | zero padding to 8 | arrays, each
 * 8-aligned; in meta, a message is a msgpack array of its fields in order, an ndarray the msgpack
 * extension 1 holding msgpack (dtype.str, shape, offset into the array region).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <string.h>
#include <time.h>

#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

/* Field kinds, as codec._c_plan numbers them. STR_LIST and primitives are "value". */
enum { K_VALUE = 0, K_ARRAY = 1, K_MESSAGE = 2, K_OPTIONAL = 3, K_MESSAGE_LIST = 4 };

#define ARRAY_EXT 1
#define ALIGN 8
#define MAX_MESSAGE_DEPTH 32  /* nested messages; deeper ones take the Python path */
#define MAX_VALUE_DEPTH 16    /* lists inside a field value */

/* Set once by setup(), owned by this module for the life of the process. */
static PyObject *plans;            /* {message class: plan tuple or None (unsupported)} */
static PyObject *plan_builder;     /* codec._c_plan(cls) -> plan tuple or None */
static PyObject *headers_in;       /* codec._HEADERS_IN: {ext payload bytes: (dtype, shape, count, offset, nbytes)} */
static PyObject *array_header;     /* codec._array_header(bytes) -> that tuple, filling the cache */
static PyObject *encode_python;    /* codec.encode_python(msg) */
static PyObject *decode_python;    /* codec.decode_python(cls, frame, copy, arrays) */
static PyTypeObject *encoded_type; /* codec.Encoded */
static PyObject *encoded_slots;    /* (meta, arrays, array_bytes) member descriptors of Encoded */
static PyObject *dtype_strs;       /* {id(dtype): (dtype, dtype.str)}: dtype.str builds a new str per call */
static PyObject *empty_tuple;

/* ------------------------------------------------------------------------------- giving up */

/* Whether the failure just seen may be answered by taking the Python path. Exceptions that are
 * not an Exception (KeyboardInterrupt, SystemExit) must go through, not be swallowed. */
static int can_fall_back(void)
{
    PyObject *exc = PyErr_Occurred();
    if (exc == NULL)
        return 1;
    if (!PyErr_GivenExceptionMatches(exc, PyExc_Exception))
        return 0;
    PyErr_Clear();
    return 1;
}

/* --------------------------------------------------------------------------------- plans */

/* The plan of ``cls`` (borrowed), or NULL: unsupported, or an error to give up on. A plan is a
 * tuple with one (kind, accessor, nested class or None) per field, in the message's order;
 * the accessor is the slot's member descriptor, or the field's name. */
static PyObject *plan_of(PyObject *cls)
{
    PyObject *plan = PyDict_GetItemWithError(plans, cls);
    if (plan == NULL) {
        if (PyErr_Occurred())
            return NULL;
        plan = PyObject_CallOneArg(plan_builder, cls);
        if (plan == NULL)
            return NULL;
        if (plan != Py_None && !PyTuple_Check(plan)) {
            Py_DECREF(plan);
            PyErr_SetString(PyExc_TypeError, "codec._c_plan must return a tuple or None");
            return NULL;
        }
        if (PyDict_GET_SIZE(plans) >= 4096)
            PyDict_Clear(plans);  /* bounded, like every cache here: classes made on the fly */
        int failed = PyDict_SetItem(plans, cls, plan);
        Py_DECREF(plan);  /* the dict holds it */
        if (failed)
            return NULL;
    }
    return plan == Py_None ? NULL : plan;
}

static PyObject *get_field(PyObject *obj, PyObject *accessor)
{
    descrgetfunc get = Py_TYPE(accessor)->tp_descr_get;
    if (Py_IS_TYPE(accessor, &PyMemberDescr_Type) && get != NULL)
        return get(accessor, obj, (PyObject *)Py_TYPE(obj));
    return PyObject_GetAttr(obj, accessor);
}

/* Sets a field as codec.py's generated decoder does: the slot's own setter, or
 * object.__setattr__; both bypass the class's __setattr__ and so its converters. */
static int set_field(PyObject *obj, PyObject *accessor, PyObject *value)
{
    descrsetfunc set = Py_TYPE(accessor)->tp_descr_set;
    if (Py_IS_TYPE(accessor, &PyMemberDescr_Type) && set != NULL)
        return set(accessor, obj, value);
    return PyObject_GenericSetAttr(obj, accessor, value);
}

/* ================================================================================ encoding */

typedef struct {
    char *data;
    Py_ssize_t len, cap;
    char local[256];  /* most messages' metadata fits: no allocation */
} writer;

static int reserve(writer *w, Py_ssize_t n)
{
    if (w->len + n <= w->cap)
        return 0;
    Py_ssize_t cap = w->cap * 2;
    if (cap < w->len + n)
        cap = w->len + n;
    char *grown;
    if (w->data == w->local) {
        grown = PyMem_Malloc(cap);
        if (grown != NULL)
            memcpy(grown, w->local, w->len);
    } else {
        grown = PyMem_Realloc(w->data, cap);
    }
    if (grown == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    w->data = grown;
    w->cap = cap;
    return 0;
}

static int put_bytes(writer *w, const void *src, Py_ssize_t n)
{
    if (reserve(w, n))
        return -1;
    memcpy(w->data + w->len, src, n);
    w->len += n;
    return 0;
}

/* A marker byte then ``size`` bytes of ``v``, big-endian (msgpack's order). */
static int put_be(writer *w, unsigned char marker, unsigned long long v, int size)
{
    if (reserve(w, 1 + size))
        return -1;
    unsigned char *p = (unsigned char *)w->data + w->len;
    p[0] = marker;
    for (int i = 0; i < size; i++)
        p[1 + i] = (unsigned char)(v >> (8 * (size - 1 - i)));
    w->len += 1 + size;
    return 0;
}

static int put_byte(writer *w, unsigned char b) { return put_be(w, b, 0, 0); }

/* The smallest encodings msgpack-python (msgpack-c's pack templates) chooses. */
static int put_uint(writer *w, unsigned long long v)
{
    if (v < 128)
        return put_byte(w, (unsigned char)v);
    if (v < 256)
        return put_be(w, 0xcc, v, 1);
    if (v < 65536)
        return put_be(w, 0xcd, v, 2);
    if (v < 4294967296ULL)
        return put_be(w, 0xce, v, 4);
    return put_be(w, 0xcf, v, 8);
}

static int put_int(writer *w, long long v)
{
    if (v >= 0)
        return put_uint(w, (unsigned long long)v);
    if (v >= -32)
        return put_byte(w, (unsigned char)(v & 0xff));
    if (v >= -128)
        return put_be(w, 0xd0, (unsigned long long)v, 1);
    if (v >= -32768)
        return put_be(w, 0xd1, (unsigned long long)v, 2);
    if (v >= -2147483648LL)
        return put_be(w, 0xd2, (unsigned long long)v, 4);
    return put_be(w, 0xd3, (unsigned long long)v, 8);
}

static int put_array_header(writer *w, Py_ssize_t n)
{
    if (n < 16)
        return put_byte(w, (unsigned char)(0x90 | n));
    if (n < 65536)
        return put_be(w, 0xdc, (unsigned long long)n, 2);
    if ((unsigned long long)n <= 0xffffffffULL)
        return put_be(w, 0xdd, (unsigned long long)n, 4);
    return -2;
}

static int put_str(writer *w, const char *s, Py_ssize_t n)
{
    int r;
    if (n < 32)
        r = put_byte(w, (unsigned char)(0xa0 | n));
    else if (n < 256)
        r = put_be(w, 0xd9, (unsigned long long)n, 1);
    else if (n < 65536)
        r = put_be(w, 0xda, (unsigned long long)n, 2);
    else if ((unsigned long long)n <= 0xffffffffULL)
        r = put_be(w, 0xdb, (unsigned long long)n, 4);
    else
        return -2;
    return r ? r : put_bytes(w, s, n);
}

/* Return codes of the encoder's steps: 0 done, -1 error (exception set), -2 give up. */

/* A field value that is not a message or an array: None, bool, int, float, str, and lists or
 * tuples of those (a STR_LIST). Anything else (a numpy scalar, a dict, an int subclass) gives
 * up: the Python codec packs it however msgpack does. */
static int put_value(writer *w, PyObject *v, int depth)
{
    if (v == Py_None)
        return put_byte(w, 0xc0);
    if (v == Py_True)
        return put_byte(w, 0xc3);
    if (v == Py_False)
        return put_byte(w, 0xc2);
    if (PyLong_CheckExact(v)) {
        int overflow;
        long long x = PyLong_AsLongLongAndOverflow(v, &overflow);
        if (overflow > 0) {
            unsigned long long u = PyLong_AsUnsignedLongLong(v);
            if (u == (unsigned long long)-1 && PyErr_Occurred())
                return -2;
            return put_uint(w, u);
        }
        if (overflow < 0 || (x == -1 && PyErr_Occurred()))
            return -2;
        return put_int(w, x);
    }
    if (PyFloat_CheckExact(v)) {
        double d = PyFloat_AS_DOUBLE(v);
        unsigned long long bits;
        memcpy(&bits, &d, 8);
        return put_be(w, 0xcb, bits, 8);
    }
    if (PyUnicode_CheckExact(v)) {
        Py_ssize_t n;
        const char *s = PyUnicode_AsUTF8AndSize(v, &n);
        if (s == NULL)
            return -2;  /* lone surrogates: msgpack raises, and so will the Python path */
        return put_str(w, s, n);
    }
    if (PyList_CheckExact(v) || PyTuple_CheckExact(v)) {
        if (depth >= MAX_VALUE_DEPTH)
            return -2;
        PyObject *seq = v;
        Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
        int r = put_array_header(w, n);
        if (r)
            return r;
        for (Py_ssize_t i = 0; i < n; i++) {
            /* A list may change under us only through code we call; we call none here. */
            r = put_value(w, PySequence_Fast_GET_ITEM(seq, i), depth + 1);
            if (r)
                return r;
        }
        return 0;
    }
    return -2;
}

typedef struct {
    writer w;
    PyObject *arrays;      /* list of the message's arrays, in order */
    Py_ssize_t offset;     /* next array's offset in the array region */
} encoder;

/* dtype.str, through a cache (borrowed reference), or NULL. */
static PyObject *dtype_str_cached(PyArray_Descr *descr);

/* The last dtype seen and its str (strong references): a topic's messages nearly always repeat it,
 * and one comparison is cheaper than the dict's hashing when caches are cold. */
static PyArray_Descr *last_descr;
static PyObject *last_descr_str;

static PyObject *dtype_str(PyArray_Descr *descr)
{
    if (descr == last_descr)
        return last_descr_str;
    PyObject *str = dtype_str_cached(descr);
    if (str != NULL) {
        Py_INCREF(descr);
        Py_INCREF(str);
        Py_XSETREF(last_descr, descr);
        Py_XSETREF(last_descr_str, str);
    }
    return str;
}

static PyObject *dtype_str_cached(PyArray_Descr *descr)
{
    PyObject *key = PyLong_FromVoidPtr(descr);
    if (key == NULL)
        return NULL;
    PyObject *entry = PyDict_GetItemWithError(dtype_strs, key);
    if (entry != NULL && PyTuple_GET_ITEM(entry, 0) == (PyObject *)descr) {
        Py_DECREF(key);
        return PyTuple_GET_ITEM(entry, 1);
    }
    if (PyErr_Occurred()) {
        Py_DECREF(key);
        return NULL;
    }
    PyObject *str = PyObject_GetAttrString((PyObject *)descr, "str");
    if (str == NULL || !PyUnicode_CheckExact(str)) {
        Py_XDECREF(str);
        Py_DECREF(key);
        return NULL;
    }
    /* The entry keeps its dtype alive, so a recycled address can never name another dtype. */
    entry = PyTuple_Pack(2, (PyObject *)descr, str);
    Py_DECREF(str);
    if (entry == NULL) {
        Py_DECREF(key);
        return NULL;
    }
    if (PyDict_GET_SIZE(dtype_strs) >= 4096)
        PyDict_Clear(dtype_strs);
    int failed = PyDict_SetItem(dtype_strs, key, entry);
    Py_DECREF(key);
    Py_DECREF(entry);
    if (failed)
        return NULL;
    return PyTuple_GET_ITEM(entry, 1);  /* alive: the dict holds the entry */
}

/* An ndarray field: the extension (dtype.str, shape, offset), the array kept for the region. */
static int put_array(encoder *e, PyObject *v)
{
    if (!PyArray_CheckExact(v))
        return -2;
    PyArrayObject *arr = (PyArrayObject *)v;
    PyArray_Descr *descr = PyArray_DESCR(arr);
    if (!PyArray_IS_C_CONTIGUOUS(arr) || PyDataType_REFCHK(descr) || PyDataType_HASFIELDS(descr) || PyDataType_HASSUBARRAY(descr))
        return -2;  /* the Python codec copies, or refuses with its own message */
    PyObject *str = dtype_str(descr);
    if (str == NULL)
        return can_fall_back() ? -2 : -1;
    Py_ssize_t str_len;
    const char *s = PyUnicode_AsUTF8AndSize(str, &str_len);
    if (s == NULL)
        return can_fall_back() ? -2 : -1;

    /* The extension's payload: msgpack of (dtype.str, shape, offset), built apart to know its length. */
    writer ext = {.data = NULL, .len = 0, .cap = sizeof(ext.local)};
    ext.data = ext.local;
    int nd = PyArray_NDIM(arr);
    npy_intp *dims = PyArray_DIMS(arr);
    int r = put_byte(&ext, 0x93);
    if (!r) r = put_str(&ext, s, str_len);
    if (!r) r = put_array_header(&ext, nd);
    for (int i = 0; i < nd && !r; i++)
        r = put_int(&ext, (long long)dims[i]);
    if (!r) r = put_int(&ext, (long long)e->offset);
    if (!r) {
        Py_ssize_t n = ext.len;
        switch (n) {
        case 1: r = put_byte(&e->w, 0xd4); break;
        case 2: r = put_byte(&e->w, 0xd5); break;
        case 4: r = put_byte(&e->w, 0xd6); break;
        case 8: r = put_byte(&e->w, 0xd7); break;
        case 16: r = put_byte(&e->w, 0xd8); break;
        default:
            r = n < 256 ? put_be(&e->w, 0xc7, (unsigned long long)n, 1)
              : n < 65536 ? put_be(&e->w, 0xc8, (unsigned long long)n, 2)
              : put_be(&e->w, 0xc9, (unsigned long long)n, 4);
        }
        if (!r) r = put_byte(&e->w, ARRAY_EXT);
        if (!r) r = put_bytes(&e->w, ext.data, n);
    }
    if (ext.data != ext.local)
        PyMem_Free(ext.data);
    if (r)
        return r;
    if (PyList_Append(e->arrays, v))
        return -1;
    Py_ssize_t nbytes = PyArray_NBYTES(arr);
    e->offset += (nbytes + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
    return 0;
}

static int put_message(encoder *e, PyObject *msg, PyObject *cls, int depth);

static int put_field(encoder *e, long kind, PyObject *v, PyObject *nested, int depth)
{
    switch (kind) {
    case K_VALUE:
        return put_value(&e->w, v, 0);
    case K_ARRAY:
        return put_array(e, v);
    case K_OPTIONAL:
        if (v == Py_None)
            return put_byte(&e->w, 0xc0);
        /* fall through */
    case K_MESSAGE:
        return put_message(e, v, nested, depth + 1);
    case K_MESSAGE_LIST: {
        if (!PyList_CheckExact(v))
            return -2;
        Py_ssize_t n = PyList_GET_SIZE(v);
        int r = put_array_header(&e->w, n);
        for (Py_ssize_t i = 0; i < n && !r; i++) {
            if (i >= PyList_GET_SIZE(v))
                return -2;  /* shrunk while we read it (a getter ran code): take the Python path */
            PyObject *item = PyList_GET_ITEM(v, i);
            Py_INCREF(item);
            r = put_message(e, item, nested, depth + 1);
            Py_DECREF(item);
        }
        return r;
    }
    }
    return -2;
}

/* ``msg``, which must be exactly of class ``cls`` (a subclass may hold more than the declared
 * fields: the Python codec's business). */
static int put_message(encoder *e, PyObject *msg, PyObject *cls, int depth)
{
    if (depth >= MAX_MESSAGE_DEPTH || (PyObject *)Py_TYPE(msg) != cls)
        return -2;
    PyObject *plan = plan_of(cls);
    if (plan == NULL)
        return can_fall_back() ? -2 : -1;
    Py_INCREF(plan);  /* a getter could clear the cache */
    Py_ssize_t n = PyTuple_GET_SIZE(plan);
    int r = put_array_header(&e->w, n);
    for (Py_ssize_t i = 0; i < n && !r; i++) {
        PyObject *field = PyTuple_GET_ITEM(plan, i);
        PyObject *v = get_field(msg, PyTuple_GET_ITEM(field, 1));
        if (v == NULL) {
            r = can_fall_back() ? -2 : -1;
            break;
        }
        r = put_field(e, PyLong_AsLong(PyTuple_GET_ITEM(field, 0)), v, PyTuple_GET_ITEM(field, 2), depth);
        Py_DECREF(v);
    }
    Py_DECREF(plan);
    return r;
}

/* Sets the three slots of a new codec.Encoded. */
static PyObject *make_encoded(PyObject *meta, PyObject *arrays, Py_ssize_t array_bytes)
{
    PyObject *enc = PyBaseObject_Type.tp_new(encoded_type, empty_tuple, NULL);
    if (enc == NULL)
        return NULL;
    PyObject *size = PyLong_FromSsize_t(array_bytes);
    if (size == NULL || set_field(enc, PyTuple_GET_ITEM(encoded_slots, 0), meta) || set_field(enc, PyTuple_GET_ITEM(encoded_slots, 1), arrays)
        || set_field(enc, PyTuple_GET_ITEM(encoded_slots, 2), size)) {
        Py_XDECREF(size);
        Py_DECREF(enc);
        return NULL;
    }
    Py_DECREF(size);
    return enc;
}

/* The fast path: an Encoded, or NotImplemented. */
static PyObject *try_encode_impl(PyObject *msg)
{
    encoder e = {.arrays = PyList_New(0), .offset = 0};
    if (e.arrays == NULL)
        return NULL;
    e.w.data = e.w.local;
    e.w.len = 0;
    e.w.cap = sizeof(e.w.local);
    int r = put_message(&e, msg, (PyObject *)Py_TYPE(msg), 0);
    PyObject *out = NULL;
    if (r == 0) {
        PyObject *meta = PyBytes_FromStringAndSize(e.w.data, e.w.len);
        if (meta != NULL) {
            out = make_encoded(meta, e.arrays, e.offset);
            Py_DECREF(meta);
        }
    } else if (r == -2 && can_fall_back()) {
        out = Py_NewRef(Py_NotImplemented);
    }
    if (e.w.data != e.w.local)
        PyMem_Free(e.w.data);
    Py_DECREF(e.arrays);
    return out;
}

static PyObject *try_encode(PyObject *self, PyObject *msg) { return try_encode_impl(msg); }

static PyObject *encode(PyObject *self, PyObject *msg)
{
    PyObject *out = try_encode_impl(msg);
    if (out == Py_NotImplemented) {
        Py_DECREF(out);
        return PyObject_CallOneArg(encode_python, msg);
    }
    return out;
}

/* ================================================================================ decoding */

typedef struct {
    const unsigned char *p;  /* the metadata */
    Py_ssize_t pos, end;
    PyObject *owner;         /* every array's base: the object whose bytes hold the region */
    const char *region_data;
    Py_ssize_t base, region_end;
    int readonly, copy;
} reader;

/* Return NULL to give up (an exception may be set: the caller decides, see can_fall_back). */

static int take(reader *r, Py_ssize_t n, const unsigned char **out)
{
    if (n < 0 || n > r->end - r->pos)
        return -1;
    *out = r->p + r->pos;
    r->pos += n;
    return 0;
}

static int take_be(reader *r, int size, unsigned long long *out)
{
    const unsigned char *q;
    if (take(r, size, &q))
        return -1;
    unsigned long long v = 0;
    for (int i = 0; i < size; i++)
        v = (v << 8) | q[i];
    *out = v;
    return 0;
}

/* The element count of a msgpack array at the cursor, or -1 if there is none. */
static Py_ssize_t take_array_header(reader *r)
{
    if (r->pos >= r->end)
        return -1;
    unsigned char m = r->p[r->pos];
    unsigned long long n;
    if ((m & 0xf0) == 0x90) {
        r->pos++;
        n = m & 0x0f;
    } else if (m == 0xdc || m == 0xdd) {
        r->pos++;
        if (take_be(r, m == 0xdc ? 2 : 4, &n))
            return -1;
    } else {
        return -1;
    }
    if (n > (unsigned long long)(r->end - r->pos))
        return -1;  /* every element takes at least a byte: a lie about the count stops here */
    return (Py_ssize_t)n;
}

/* The last array header read and what codec._array_header made of it (a strong reference): as
 * dtype_str's, one comparison instead of a bytes object, its hash and a dict lookup. */
static unsigned char last_ext[64];
static Py_ssize_t last_ext_len = -1;
static PyObject *last_spec;

static PyObject *array_spec(const unsigned char *data, Py_ssize_t n)
{
    if (n == last_ext_len && memcmp(data, last_ext, n) == 0)
        return Py_NewRef(last_spec);
    PyObject *key = PyBytes_FromStringAndSize((const char *)data, n);
    if (key == NULL)
        return NULL;
    PyObject *spec = PyDict_GetItemWithError(headers_in, key);
    if (spec != NULL) {
        Py_INCREF(spec);
    } else if (!PyErr_Occurred()) {
        spec = PyObject_CallOneArg(array_header, key);  /* checks it, and fills the cache */
    }
    Py_DECREF(key);
    if (spec != NULL && n <= (Py_ssize_t)sizeof(last_ext)) {
        memcpy(last_ext, data, n);
        last_ext_len = n;
        Py_XSETREF(last_spec, Py_NewRef(spec));
    }
    return spec;
}

static PyObject *read_array_ext(reader *r, const unsigned char *data, Py_ssize_t n)
{
    PyObject *spec = array_spec(data, n);
    if (spec == NULL)
        return NULL;
    PyObject *arr = NULL;
    npy_intp dims[NPY_MAXDIMS];
    if (!PyTuple_CheckExact(spec) || PyTuple_GET_SIZE(spec) != 5)
        goto done;
    PyObject *dtype = PyTuple_GET_ITEM(spec, 0), *shape = PyTuple_GET_ITEM(spec, 1);
    if (!PyArray_DescrCheck(dtype) || !PyTuple_CheckExact(shape) || PyTuple_GET_SIZE(shape) > NPY_MAXDIMS)
        goto done;
    int nd = (int)PyTuple_GET_SIZE(shape);
    for (int i = 0; i < nd; i++) {
        dims[i] = PyLong_AsSsize_t(PyTuple_GET_ITEM(shape, i));
        if (dims[i] < 0)
            goto done;
    }
    Py_ssize_t offset = PyLong_AsSsize_t(PyTuple_GET_ITEM(spec, 3));
    Py_ssize_t nbytes = PyLong_AsSsize_t(PyTuple_GET_ITEM(spec, 4));
    Py_ssize_t room = r->region_end - r->base;
    if (offset < 0 || nbytes < 0 || offset > room || nbytes > room - offset)
        goto done;  /* past the end of the frame (or a size no machine holds): the Python path says so */
    Py_INCREF(dtype);  /* stolen by NewFromDescr */
    arr = PyArray_NewFromDescr(&PyArray_Type, (PyArray_Descr *)dtype, nd, dims, NULL, (void *)(r->region_data + r->base + offset),
                               r->readonly ? 0 : NPY_ARRAY_WRITEABLE, NULL);
    if (arr == NULL)
        goto done;
    Py_INCREF(r->owner);
    if (PyArray_SetBaseObject((PyArrayObject *)arr, r->owner) < 0) {
        Py_CLEAR(arr);
        goto done;
    }
    PyArray_UpdateFlags((PyArrayObject *)arr, NPY_ARRAY_UPDATE_ALL);  /* alignment, as numpy's own constructor finds it */
    if (r->copy) {
        PyObject *owned = PyArray_NewCopy((PyArrayObject *)arr, NPY_CORDER);
        Py_SETREF(arr, owned);
    }
done:
    Py_DECREF(spec);
    return arr;
}

/* Any msgpack value msgpack.unpackb(raw=False) would give, for what this codec writes: nil,
 * booleans, integers, floats, str, bin, arrays (lists) and our array extension. Maps, other
 * extensions, and anything malformed give up. */
static PyObject *read_value(reader *r, int depth)
{
    if (r->pos >= r->end)
        return NULL;
    unsigned char m = r->p[r->pos++];
    unsigned long long u;
    const unsigned char *q;
    if (m <= 0x7f)
        return PyLong_FromLong(m);
    if (m >= 0xe0)
        return PyLong_FromLong((long)(signed char)m);
    if ((m & 0xe0) == 0xa0 || m == 0xd9 || m == 0xda || m == 0xdb) {
        Py_ssize_t n = m & 0x1f;
        if (m >= 0xd9) {
            if (take_be(r, m == 0xd9 ? 1 : m == 0xda ? 2 : 4, &u))
                return NULL;
            n = (Py_ssize_t)u;
        }
        if (take(r, n, &q))
            return NULL;
        return PyUnicode_DecodeUTF8((const char *)q, n, "strict");
    }
    if ((m & 0xf0) == 0x90 || m == 0xdc || m == 0xdd) {
        r->pos--;
        Py_ssize_t n = take_array_header(r);
        if (n < 0 || depth >= MAX_VALUE_DEPTH)
            return NULL;
        PyObject *list = PyList_New(n);
        if (list == NULL)
            return NULL;
        for (Py_ssize_t i = 0; i < n; i++) {
            PyObject *item = read_value(r, depth + 1);
            if (item == NULL) {
                Py_DECREF(list);
                return NULL;
            }
            PyList_SET_ITEM(list, i, item);
        }
        return list;
    }
    switch (m) {
    case 0xc0: return Py_NewRef(Py_None);
    case 0xc2: return Py_NewRef(Py_False);
    case 0xc3: return Py_NewRef(Py_True);
    case 0xc4: case 0xc5: case 0xc6:
        if (take_be(r, m == 0xc4 ? 1 : m == 0xc5 ? 2 : 4, &u) || take(r, (Py_ssize_t)u, &q))
            return NULL;
        return PyBytes_FromStringAndSize((const char *)q, (Py_ssize_t)u);
    case 0xca: {
        if (take_be(r, 4, &u))
            return NULL;
        uint32_t bits = (uint32_t)u;
        float f;
        memcpy(&f, &bits, 4);
        return PyFloat_FromDouble((double)f);
    }
    case 0xcb: {
        if (take_be(r, 8, &u))
            return NULL;
        double d;
        memcpy(&d, &u, 8);
        return PyFloat_FromDouble(d);
    }
    case 0xcc: case 0xcd: case 0xce: case 0xcf:
        if (take_be(r, 1 << (m - 0xcc), &u))
            return NULL;
        return PyLong_FromUnsignedLongLong(u);
    case 0xd0: case 0xd1: case 0xd2: case 0xd3: {
        int size = 1 << (m - 0xd0);
        if (take_be(r, size, &u))
            return NULL;
        long long v = size == 8 ? (long long)u : (long long)(u ^ (1ULL << (8 * size - 1))) - (long long)(1ULL << (8 * size - 1));
        return PyLong_FromLongLong(v);
    }
    case 0xd4: case 0xd5: case 0xd6: case 0xd7: case 0xd8:
    case 0xc7: case 0xc8: case 0xc9: {
        Py_ssize_t n;
        if (m >= 0xd4) {
            n = (Py_ssize_t)1 << (m - 0xd4);
        } else {
            if (take_be(r, m == 0xc7 ? 1 : m == 0xc8 ? 2 : 4, &u))
                return NULL;
            n = (Py_ssize_t)u;
        }
        const unsigned char *code;
        if (take(r, 1, &code) || take(r, n, &q) || *code != ARRAY_EXT)
            return NULL;
        return read_array_ext(r, q, n);
    }
    }
    return NULL;
}

static PyObject *read_message(reader *r, PyObject *cls, int depth)
{
    if (depth >= MAX_MESSAGE_DEPTH)
        return NULL;
    PyObject *plan = plan_of(cls);
    if (plan == NULL)
        return NULL;
    Py_ssize_t n = take_array_header(r);
    if (n != PyTuple_GET_SIZE(plan))
        return NULL;
    Py_INCREF(plan);
    PyObject *obj = PyBaseObject_Type.tp_new((PyTypeObject *)cls, empty_tuple, NULL);  /* object.__new__(cls) */
    for (Py_ssize_t i = 0; i < n && obj != NULL; i++) {
        PyObject *field = PyTuple_GET_ITEM(plan, i);
        long kind = PyLong_AsLong(PyTuple_GET_ITEM(field, 0));
        PyObject *nested = PyTuple_GET_ITEM(field, 2), *v = NULL;
        if (kind == K_MESSAGE || kind == K_OPTIONAL) {
            if (kind == K_OPTIONAL && r->pos < r->end && r->p[r->pos] == 0xc0) {
                r->pos++;
                v = Py_NewRef(Py_None);
            } else {
                v = read_message(r, nested, depth + 1);
            }
        } else if (kind == K_MESSAGE_LIST) {
            Py_ssize_t count = take_array_header(r);
            v = count < 0 ? NULL : PyList_New(count);
            for (Py_ssize_t j = 0; j < count && v != NULL; j++) {
                PyObject *item = read_message(r, nested, depth + 1);
                if (item == NULL)
                    Py_CLEAR(v);
                else
                    PyList_SET_ITEM(v, j, item);
            }
        } else {
            v = read_value(r, 0);
        }
        if (v == NULL || set_field(obj, PyTuple_GET_ITEM(field, 1), v))
            Py_CLEAR(obj);
        Py_XDECREF(v);
    }
    Py_DECREF(plan);
    return obj;
}

/* The message frame at p[0:len] (u32 meta_len | meta | padding | arrays), or NULL to give up.
 * Its arrays are views of region_data[0:region_len], which is the frame itself (``split`` 0:
 * offsets count from the end of the metadata's padding) or the array region of a message in two
 * parts (``split`` 1: from its start). ``owner``: the object holding those bytes, every array's
 * base, as numpy's own constructor makes it from a memoryview (see owner_of; as there, no
 * buffer export is held: the owner keeps the bytes alive). */
static PyObject *decode_at(PyObject *cls, const unsigned char *p, Py_ssize_t len, PyObject *owner, const char *region_data,
                           Py_ssize_t region_len, int split, int readonly, int copy)
{
    if (len < 4)
        return NULL;
    unsigned long long meta_len = (unsigned long long)p[0] | ((unsigned long long)p[1] << 8) | ((unsigned long long)p[2] << 16)
                                  | ((unsigned long long)p[3] << 24);
    unsigned long long base = (4 + meta_len + ALIGN - 1) & ~(unsigned long long)(ALIGN - 1);
    if (base > (unsigned long long)len)
        return NULL;
    reader r = {.p = p + 4, .pos = 0, .end = (Py_ssize_t)meta_len, .owner = owner, .region_data = region_data,
                .base = split ? 0 : (Py_ssize_t)base, .region_end = region_len, .readonly = readonly, .copy = copy};
    PyObject *out = read_message(&r, cls, 0);
    if (out != NULL && r.pos != r.end)
        Py_CLEAR(out);  /* bytes after the message: msgpack's ExtraData */
    return out;
}

/* A memoryview of ``obj`` if it is flat bytes, else NULL: what len() and slicing mean for
 * other buffers is the Python path's call. */
static PyObject *flat_view(PyObject *obj)
{
    PyObject *view = PyMemoryView_FromObject(obj);
    if (view == NULL)
        return NULL;
    Py_buffer *buf = PyMemoryView_GET_BUFFER(view);
    if (buf->ndim > 1 || buf->itemsize != 1 || !PyBuffer_IsContiguous(buf, 'C')) {
        Py_DECREF(view);
        return NULL;
    }
    return view;
}

/* What numpy's constructor takes as an array's base given a buffer through memoryview ``view``:
 * the object the view looks at (borrowed). */
static PyObject *owner_of(PyObject *view)
{
    PyObject *owner = PyMemoryView_GET_BASE(view);
    return owner != NULL ? owner : view;
}

/* The fast path of decode(cls, frame, copy, arrays): the message, NotImplemented, or NULL with
 * an exception that is not an Exception. */
static PyObject *try_decode_impl(PyObject *cls, PyObject *frame, int copy, PyObject *arrays)
{
    PyObject *view = NULL, *region = NULL, *out = NULL;
    if (!PyType_Check(cls) || (view = flat_view(frame)) == NULL)
        goto give_up;
    region = arrays == Py_None ? Py_NewRef(view) : flat_view(arrays);
    if (region == NULL)
        goto give_up;
    Py_buffer *buf = PyMemoryView_GET_BUFFER(view), *rbuf = PyMemoryView_GET_BUFFER(region);
    out = decode_at(cls, buf->buf, buf->len, owner_of(region), rbuf->buf, rbuf->len, arrays != Py_None, rbuf->readonly, copy);
    if (out != NULL)
        goto done;
give_up:
    if (can_fall_back())
        out = Py_NewRef(Py_NotImplemented);
done:
    Py_XDECREF(region);
    Py_XDECREF(view);
    return out;
}

static int parse_decode_args(PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames, PyObject **cls, PyObject **frame, int *copy,
                             PyObject **arrays)
{
    static const char *names[] = {"cls", "frame", "copy", "arrays"};
    PyObject *values[4] = {NULL, NULL, Py_False, Py_None};
    if (nargs > 4) {
        PyErr_Format(PyExc_TypeError, "decode() takes at most 4 arguments (%zd given)", nargs);
        return -1;
    }
    for (Py_ssize_t i = 0; i < nargs; i++)
        values[i] = args[i];
    Py_ssize_t nkw = kwnames == NULL ? 0 : PyTuple_GET_SIZE(kwnames);
    for (Py_ssize_t k = 0; k < nkw; k++) {
        PyObject *name = PyTuple_GET_ITEM(kwnames, k);
        int found = 0;
        for (int i = 0; i < 4; i++) {
            if (PyUnicode_CompareWithASCIIString(name, names[i]) == 0) {
                if (i < nargs) {
                    PyErr_Format(PyExc_TypeError, "decode() got multiple values for argument '%s'", names[i]);
                    return -1;
                }
                values[i] = args[nargs + k];
                found = 1;
            }
        }
        if (!found) {
            PyErr_Format(PyExc_TypeError, "decode() got an unexpected keyword argument '%U'", name);
            return -1;
        }
    }
    if (values[0] == NULL || values[1] == NULL) {
        PyErr_SetString(PyExc_TypeError, "decode() needs a message class and a frame");
        return -1;
    }
    int truth = PyObject_IsTrue(values[2]);
    if (truth < 0)
        return -1;
    *cls = values[0];
    *frame = values[1];
    *copy = truth;
    *arrays = values[3];
    return 0;
}

static PyObject *try_decode(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    PyObject *cls, *frame, *arrays;
    int copy;
    if (parse_decode_args(args, nargs, kwnames, &cls, &frame, &copy, &arrays))
        return NULL;
    return try_decode_impl(cls, frame, copy, arrays);
}

static PyObject *decode(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    PyObject *cls, *frame, *arrays;
    int copy;
    if (parse_decode_args(args, nargs, kwnames, &cls, &frame, &copy, &arrays))
        return NULL;
    PyObject *out = try_decode_impl(cls, frame, copy, arrays);
    if (out == Py_NotImplemented) {
        Py_DECREF(out);
        PyObject *call[4] = {cls, frame, copy ? Py_True : Py_False, arrays};
        return PyObject_Vectorcall(decode_python, call, 4, NULL);
    }
    return out;
}

/* ========================================================================== network frames */
/* emos/transport/netframe.py's frame of one message on Zenoh: "EMZ1" | stamp_ns u64 |
 * fingerprint length u16 | publisher length u16 | fingerprint | publisher | padding to 8 |
 * the message frame above. Both functions fall back to netframe's Python code as the codec's do. */

#define NET_HEADER 16
#define NET_MAX_NAME 1024  /* netframe.MAX_NAME_BYTES */

static PyObject *read_message_python; /* netframe.read_message_python(data, fingerprint, cls) */
static PyObject *checked_names;       /* netframe._checked: {(fingerprint, lengths + names): publisher} */
/* The last frame's names that checked_names accepted, for the fingerprint object the subscriber
 * passed (strong references): a topic's frames nearly always come from the publisher of the
 * one before, and one comparison spares a bytes object, a tuple, their hashes and a lookup. */
static PyObject *last_fingerprint, *last_publisher;
static unsigned char last_names[4 + 2 * NET_MAX_NAME];
static Py_ssize_t last_names_len = -1;

static void put_le(char *q, unsigned long long v, int size)
{
    for (int i = 0; i < size; i++)
        q[i] = (char)(v >> (8 * i));
}

/* frame_message(msg, header, stamp_ns or None (now), limit): the whole frame as bytes when the message's
 * metadata and arrays take fewer than ``limit`` bytes; else (or when the fast path gives up)
 * the message's Encoded, for netframe to frame. ``header``: the publisher's constant frame
 * start, stamp bytes included (overwritten), its length a multiple of 8. */
static PyObject *frame_message(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4 || !PyBytes_CheckExact(args[1]) || PyBytes_GET_SIZE(args[1]) < NET_HEADER || PyBytes_GET_SIZE(args[1]) % ALIGN) {
        PyErr_SetString(PyExc_TypeError, "frame_message(msg, header: bytes of a multiple of 8 >= 16, stamp_ns, limit)");
        return NULL;
    }
    PyObject *msg = args[0], *header = args[1];
    unsigned long long stamp;
    if (args[2] == Py_None) {  /* now, as time.time_ns() would say, without a call into Python */
        struct timespec now;
        clock_gettime(CLOCK_REALTIME, &now);
        stamp = (unsigned long long)now.tv_sec * 1000000000ULL + (unsigned long long)now.tv_nsec;
    } else {
        stamp = PyLong_AsUnsignedLongLong(args[2]);
        if (stamp == (unsigned long long)-1 && PyErr_Occurred())
            return NULL;
    }
    Py_ssize_t limit = PyLong_AsSsize_t(args[3]);
    if (limit == -1 && PyErr_Occurred())
        return NULL;
    encoder e = {.arrays = PyList_New(0), .offset = 0};
    if (e.arrays == NULL)
        return NULL;
    e.w.data = e.w.local;
    e.w.len = 0;
    e.w.cap = sizeof(e.w.local);
    PyObject *out = NULL;
    int r = put_message(&e, msg, (PyObject *)Py_TYPE(msg), 0);
    if (r == -2 && can_fall_back()) {
        out = PyObject_CallOneArg(encode_python, msg);
    } else if (r == 0 && e.w.len + e.offset >= limit) {
        PyObject *meta = PyBytes_FromStringAndSize(e.w.data, e.w.len);
        if (meta != NULL) {
            out = make_encoded(meta, e.arrays, e.offset);
            Py_DECREF(meta);
        }
    } else if (r == 0) {
        Py_ssize_t head = PyBytes_GET_SIZE(header), meta_end = (4 + e.w.len + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
        out = PyBytes_FromStringAndSize(NULL, head + meta_end + e.offset);
        if (out != NULL) {
            char *q = PyBytes_AS_STRING(out);
            memcpy(q, PyBytes_AS_STRING(header), head);
            put_le(q + 4, stamp, 8);
            q += head;
            put_le(q, (unsigned long long)e.w.len, 4);
            memcpy(q + 4, e.w.data, e.w.len);
            memset(q + 4 + e.w.len, 0, meta_end - 4 - e.w.len);
            Py_ssize_t pos = meta_end;
            for (Py_ssize_t i = 0; i < PyList_GET_SIZE(e.arrays); i++) {
                PyArrayObject *arr = (PyArrayObject *)PyList_GET_ITEM(e.arrays, i);
                Py_ssize_t n = PyArray_NBYTES(arr), padded = (n + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
                memcpy(q + pos, PyArray_DATA(arr), n);  /* C-contiguous: put_array checked */
                memset(q + pos + n, 0, padded - n);
                pos += padded;
            }
        }
    }
    if (e.w.data != e.w.local)
        PyMem_Free(e.w.data);
    Py_DECREF(e.arrays);
    return out;
}

/* The fast path of read_message: (stamp_ns, publisher, message), or NULL to give up. Only
 * whole frames from a publisher whose names netframe has already checked (in checked_names):
 * a new publisher's first frame, like every bad one, takes the Python path. */
static PyObject *try_read_framed(PyObject *data, PyObject *fingerprint, PyObject *cls)
{
    PyObject *view = NULL, *out = NULL, *names = NULL, *key = NULL, *msg = NULL, *owner = data;
    const unsigned char *p;
    Py_ssize_t size;
    if (!PyBytes_CheckExact(fingerprint) || !PyType_Check(cls))
        goto done;
    if (PyBytes_CheckExact(data)) {  /* what Zenoh's payload.to_bytes() gives: no view needed */
        p = (const unsigned char *)PyBytes_AS_STRING(data);
        size = PyBytes_GET_SIZE(data);
    } else {
        if ((view = flat_view(data)) == NULL)
            goto done;
        p = PyMemoryView_GET_BUFFER(view)->buf;
        size = PyMemoryView_GET_BUFFER(view)->len;
        owner = owner_of(view);
    }
    if (size < NET_HEADER || memcmp(p, "EMZ1", 4) != 0)
        goto done;
    unsigned long long stamp = 0;
    for (int i = 7; i >= 0; i--)
        stamp = (stamp << 8) | p[4 + i];
    Py_ssize_t fp_len = p[12] | (p[13] << 8), pub_len = p[14] | (p[15] << 8);
    if (fp_len > NET_MAX_NAME || pub_len > NET_MAX_NAME)
        goto done;
    Py_ssize_t head = NET_HEADER + fp_len + pub_len, start = (head + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
    if (start > size)
        goto done;
    PyObject *pub;
    Py_ssize_t names_len = head - 12;
    if (fingerprint == last_fingerprint && names_len == last_names_len && memcmp(p + 12, last_names, names_len) == 0) {
        pub = Py_NewRef(last_publisher);  /* the same publisher as the last frame: checked then */
    } else {
        names = PyBytes_FromStringAndSize((const char *)p + 12, names_len);
        key = names == NULL ? NULL : PyTuple_Pack(2, fingerprint, names);
        pub = key == NULL ? NULL : PyDict_GetItemWithError(checked_names, key);
        if (pub == NULL)
            goto done;
        Py_INCREF(pub);
        memcpy(last_names, p + 12, names_len);  /* names_len <= 4 + 2 * NET_MAX_NAME: checked above */
        last_names_len = names_len;
        Py_XSETREF(last_fingerprint, Py_NewRef(fingerprint));
        Py_XSETREF(last_publisher, Py_NewRef(pub));
    }
    /* Read-only arrays, whatever ``data`` is, as netframe.read_frame's read-only view makes them. */
    msg = decode_at(cls, p + start, size - start, owner, (const char *)p + start, size - start, 0, 1, 0);
    PyObject *stamp_obj = msg == NULL ? NULL : PyLong_FromUnsignedLongLong(stamp);
    out = stamp_obj == NULL ? NULL : PyTuple_New(3);
    if (out != NULL) {
        PyTuple_SET_ITEM(out, 0, stamp_obj);
        PyTuple_SET_ITEM(out, 1, pub);
        PyTuple_SET_ITEM(out, 2, msg);
    } else {
        Py_XDECREF(stamp_obj);
        Py_DECREF(pub);
        Py_XDECREF(msg);
    }
done:
    Py_XDECREF(key);
    Py_XDECREF(names);
    Py_XDECREF(view);
    return out;
}

/* The fast path of a whole frame, then on give-up either netframe's Python reader (``python``
 * 1: read_message) or NotImplemented (0: try_read_message, for the tests). */
static PyObject *read_message_or(PyObject *const *args, Py_ssize_t nargs, int python)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "read_message(data, fingerprint, cls)");
        return NULL;
    }
    PyObject *out = try_read_framed(args[0], args[1], args[2]);
    if (out != NULL || !can_fall_back())
        return out;
    return python ? PyObject_Vectorcall(read_message_python, args, 3, NULL) : Py_NewRef(Py_NotImplemented);
}

/* read_message(data, fingerprint, cls) -> (stamp_ns, publisher, message): netframe's, fast. */
static PyObject *read_framed(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return read_message_or(args, nargs, 1); }

/* The fast path alone: the tuple, or NotImplemented. */
static PyObject *try_read_message(PyObject *self, PyObject *const *args, Py_ssize_t nargs) { return read_message_or(args, nargs, 0); }

static PyObject *setup_frames(PyObject *self, PyObject *args)
{
    PyObject *reader_fn, *checked;
    if (!PyArg_ParseTuple(args, "OO!:setup_frames", &reader_fn, &PyDict_Type, &checked))
        return NULL;
    Py_XSETREF(read_message_python, Py_NewRef(reader_fn));
    Py_XSETREF(checked_names, Py_NewRef(checked));
    Py_RETURN_NONE;
}

/* ============================================================================ streaming copy */
/* stream_copy(dst, offset, src): copy a big array into a ring slot with non-temporal stores.
 *
 * Why: a plain copy (memcpy, numpy) first takes every line of the destination into this core's
 * cache in order to overwrite it (read-for-ownership). A ring slot is the worst case for that:
 * its lines are either in memory (a ring cycles through more slots than the caches hold: two
 * rings of 8 MiB slots in a ping-pong) or in the cache of the reader's core, which read the slot
 * last and must now give them up, line by line. On this VM that transfer between the two vCPUs
 * costs anywhere from little to 4x the copy, changing as the host moves them, so every
 * plain-copy transport swung 3-6x between benchmark rounds. Streaming stores write whole lines
 * to memory without owning them first; the reader then reads memory, at full bandwidth. glibc's
 * memcpy streams only above 3/4 of what it takes for the shared cache (240 MiB on this VM).
 * docs/ipc.md, "Streaming copies", has the measurements and the threshold (codec.STREAM_MIN_BYTES).
 *
 * Ordering. Streaming stores are weakly ordered even on x86-64: they may pass earlier plain stores
 * and be passed by later ones. Without fences a reader could see the new payload under the old
 * seq, or the commit (seq = 2n+2) before the payload, and accept a torn message. So the copy is
 * bracketed by SFENCEs: the seqlock's "being written" mark is visible before the first streamed
 * byte, and every streamed byte before the function returns and the commit's plain stores follow.
 *
 * Elsewhere (no SSE2) a plain memcpy. The GIL is released for the copy: the buffers are held
 * (Py_buffer), so neither can be freed or resized meanwhile. */
#if defined(__x86_64__) || defined(_M_X64)
#include <emmintrin.h>
#include <xmmintrin.h>
#define EMOS_STREAM_STORES 1
/* Read the source this far ahead: the hardware prefetchers stop at every 4 KiB page, and a
 * cold source (the reader's copy of a message it received, straight from memory) then stalls
 * on each new page. 8 MiB from a cold source into a cold slot, one process: 495-515 us against
 * 553-587 without; a source in the cache: no change (a prefetch never faults, past the end too). */
#define EMOS_PREFETCH_AHEAD 512
#else
#define EMOS_STREAM_STORES 0
#endif

static void copy_streaming(char *dst, const char *src, size_t n)
{
#if EMOS_STREAM_STORES
    /* Streaming stores may pass earlier plain stores too: the writer's "being written" mark
     * (seq = 2n+1, stored before this copy) must be visible before any byte of the new payload. */
    _mm_sfence();
    /* Head: plain stores up to the next cache line of the destination, so that each
     * iteration below fills exactly one line (a full write-combining buffer). */
    size_t head = (64 - ((uintptr_t)dst & 63)) & 63;
    if (head > n)
        head = n;
    memcpy(dst, src, head);
    dst += head;
    src += head;
    n -= head;
    size_t lines = n / 64;
    for (size_t i = 0; i < lines; i++) {
        _mm_prefetch(src + EMOS_PREFETCH_AHEAD, _MM_HINT_NTA); /* NTA: read once, keep it out of the way */
        __m128i a = _mm_loadu_si128((const __m128i *)src);
        __m128i b = _mm_loadu_si128((const __m128i *)(src + 16));
        __m128i c = _mm_loadu_si128((const __m128i *)(src + 32));
        __m128i d = _mm_loadu_si128((const __m128i *)(src + 48));
        _mm_stream_si128((__m128i *)dst, a);
        _mm_stream_si128((__m128i *)(dst + 16), b);
        _mm_stream_si128((__m128i *)(dst + 32), c);
        _mm_stream_si128((__m128i *)(dst + 48), d);
        dst += 64;
        src += 64;
    }
    memcpy(dst, src, n - lines * 64); /* tail: less than a line */
    _mm_sfence();                      /* the streaming stores before any later store (the commit) */
#else
    memcpy(dst, src, n);
#endif
}

static PyObject *stream_copy(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_Format(PyExc_TypeError, "stream_copy(dst, offset, src) takes 3 arguments, got %zd", nargs);
        return NULL;
    }
    Py_ssize_t offset = PyLong_AsSsize_t(args[1]);
    if (offset == -1 && PyErr_Occurred())
        return NULL;
    Py_buffer dst, src;
    if (PyObject_GetBuffer(args[0], &dst, PyBUF_WRITABLE) < 0)
        return NULL;
    if (PyObject_GetBuffer(args[2], &src, PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&dst);
        return NULL;
    }
    PyObject *result = NULL;
    if (offset < 0 || offset > dst.len || src.len > dst.len - offset) {
        PyErr_Format(PyExc_ValueError, "stream_copy: %zd B at offset %zd do not fit a destination of %zd B", src.len, offset, dst.len);
    } else {
        char *to = (char *)dst.buf + offset;
        Py_BEGIN_ALLOW_THREADS
        copy_streaming(to, (const char *)src.buf, (size_t)src.len);
        Py_END_ALLOW_THREADS
        result = PyLong_FromSsize_t(offset + src.len);
    }
    PyBuffer_Release(&src);
    PyBuffer_Release(&dst);
    return result;
}

/* ============================================================================ ring fast path */
/* ring_publish / ring_take: one C call per small message for the publisher (encode, claim,
 * copy, commit) and one per batch of small messages for a subscriber (look up, copy, check),
 * where the Python path costs about 15 calls into the interpreter per message each way (4.3 us
 * of CPU per publish, 2.3 us per take and decode on this VM; docs/ipc.md, "Small messages").
 *
 * They do exactly what ring.py's Ring.begin + Encoded.write_into + Ring.commit and Ring.read
 * do, and keep its protocol and its rules (ring.py's module doc is the reference):
 *
 * - Seqlock. The writer stores seq = 2n+1, a full fence, checks the pins (Dekker's handshake
 *   with a loaning reader, whose Python side fences too), copies, then stores length and stamp,
 *   seq = 2n+2, the map entry and head, each a release store (the order the protocol needs, on
 *   x86-64 and on weakly ordered CPUs alike), and ends with a full fence before the caller reads
 *   who must be woken. The reader loads the map entry, seq (acquire), the payload, an acquire
 *   fence, and seq again; a copy is accepted only if both equal 2n+2.
 * - Trust. Every index read from the segment (head, map entries, slot numbers, lengths) is
 *   checked before use and every access is bounded by the mapping's size. Anything unexpected
 *   is not handled here: the publisher returns the Encoded message, untouched ring, and the
 *   Python path runs (it grows the ring, picks another slot, or raises its own error); the
 *   reader stops at that message and the Python path reads it (it raises RingCorrupt where the
 *   bytes do not hold together, and loans big messages).
 * - Small only. The publisher handles frames up to ``limit`` bytes (the caller's; big frames keep
 *   the announcement and streaming-copy path), the reader messages under ``copy_max`` bytes
 *   (the loan threshold): large-message paths are unchanged. */

/* The ring's header layout as u64 indices, from ring.py (ring_layout), and the slot header size. */
static Py_ssize_t r_head = -1, r_first, r_busy, r_map, r_pin, r_pins, r_slot_header, r_max_head;
static Py_ssize_t r_untracked, r_waiters, r_cursors, r_max_waiters;
static unsigned long long r_empty;

static PyObject *ring_layout(PyObject *self, PyObject *args)
{
    Py_ssize_t head, first, busy, map, pin, pins, slot_header, max_head, untracked, waiters, cursors, max_waiters;
    unsigned long long empty;
    if (!PyArg_ParseTuple(args, "nnnnnnnnKnnnn:ring_layout", &head, &first, &busy, &map, &pin, &pins, &slot_header, &max_head, &empty,
                          &untracked, &waiters, &cursors, &max_waiters))
        return NULL;
    if (head < 0 || first < 0 || busy < 0 || map < 0 || pin < 0 || pins <= 0 || slot_header < 24 || slot_header % 8 || max_head <= 0
        || untracked < 0 || waiters < 0 || cursors < 0 || max_waiters <= 0) {
        PyErr_SetString(PyExc_ValueError, "ring_layout: indices must be >= 0, pins and waiters > 0, the slot header a multiple of 8 of at least 24 B");
        return NULL;
    }
    r_head = head, r_first = first, r_busy = busy, r_map = map, r_pin = pin, r_pins = pins;
    r_slot_header = slot_header, r_max_head = max_head, r_empty = empty;
    r_untracked = untracked, r_waiters = waiters, r_cursors = cursors, r_max_waiters = max_waiters;
    Py_RETURN_NONE;
}

#define LOAD(p) __atomic_load_n((p), __ATOMIC_RELAXED)
#define LOAD_ACQ(p) __atomic_load_n((p), __ATOMIC_ACQUIRE)
#define STORE(p, v) __atomic_store_n((p), (v), __ATOMIC_RELAXED)
#define STORE_REL(p, v) __atomic_store_n((p), (v), __ATOMIC_RELEASE)
#define FULL_FENCE() __atomic_thread_fence(__ATOMIC_SEQ_CST)

/* Ring geometry arguments shared by both calls, as ring.Ring holds them. */
typedef struct {
    unsigned long long depth, physical, data_offset, stride, capacity;
} geometry;

static int parse_geometry(PyObject *const *args, geometry *g)
{
    unsigned long long *out[] = {&g->depth, &g->physical, &g->data_offset, &g->stride, &g->capacity};
    for (int i = 0; i < 5; i++) {
        *out[i] = PyLong_AsUnsignedLongLong(args[i]);
        if (*out[i] == (unsigned long long)-1 && PyErr_Occurred())
            return -1;
    }
    if (g->depth == 0 || g->data_offset % 8 || g->stride % 8) {
        PyErr_SetString(PyExc_ValueError, "ring geometry: depth must be > 0, data offset and stride multiples of 8");
        return -1;
    }
    return 0;
}

/* The start every ring call shares: ``nargs == want`` (else a TypeError naming ``signature``),
 * the layout given (ring_layout), the geometry from args[geom] on, and ``count`` unsigned
 * integers from args[first] on into ``vals``. 0, or -1 with the error set. */
static int ring_args(const char *signature, PyObject *const *args, Py_ssize_t nargs, Py_ssize_t want, Py_ssize_t geom, geometry *g,
                     Py_ssize_t first, int count, unsigned long long *vals)
{
    if (nargs != want) {
        PyErr_Format(PyExc_TypeError, "%s takes %zd arguments, got %zd", signature, want, nargs);
        return -1;
    }
    if (r_head < 0) {
        PyErr_Format(PyExc_RuntimeError, "%s: ring_layout() was not called", signature);
        return -1;
    }
    if (parse_geometry(args + geom, g) < 0)
        return -1;
    for (int i = 0; i < count; i++) {
        vals[i] = PyLong_AsUnsignedLongLong(args[first + i]);
        if (vals[i] == (unsigned long long)-1 && PyErr_Occurred())
            return -1;
    }
    return 0;
}

/* u64 index of slot ``slot``'s header, or -1 if the slot with ``room`` payload bytes does not lie
 * inside the mapping of ``len`` bytes. */
static Py_ssize_t slot_at(const geometry *g, unsigned long long slot, unsigned long long room, Py_ssize_t len)
{
    if (slot >= g->physical || g->stride > (unsigned long long)len)
        return -1;
    unsigned long long start = g->data_offset + slot * g->stride;  /* slot < 65536, stride < len: no overflow */
    if (start > (unsigned long long)len || room > (unsigned long long)len - start
        || (unsigned long long)r_slot_header > (unsigned long long)len - start - room)
        return -1;
    return (Py_ssize_t)(start / 8);
}

/* Whether every header word the writer's paths read lies inside a mapping of ``words`` u64. */
static int header_fits(const geometry *g, Py_ssize_t words)
{
    return r_map + (Py_ssize_t)g->depth <= words && r_pin + r_pins <= words && r_head < words && r_first < words && r_busy < words
        && r_untracked < words && r_waiters + r_max_waiters <= words && r_cursors + r_max_waiters <= words;
}

/* Ring._claim(slot, n, retiring): mark ``slot`` (its header at u64 ``idx``) as being written with
 * message ``n``, unless (``check_retiring``) it holds another message than the one it retires,
 * nothing or our own unfinished ``n``, or a loan pins it. 1 if claimed; 0 with the slot untouched. */
static int claim_slot(volatile unsigned long long *q, Py_ssize_t idx, unsigned long long slot, unsigned long long n, int check_retiring,
                      unsigned long long retiring)
{
    unsigned long long before = LOAD(&q[idx]);
    if (check_retiring && before && before != 2 * retiring + 2 && before != 2 * n + 1)
        return 0;
    STORE(&q[idx], 2 * n + 1);
    FULL_FENCE();  /* our mark before we look at the pins (Dekker, ring.py) */
    for (Py_ssize_t i = 0; i < r_pins; i++)
        if (LOAD(&q[r_pin + i]) == slot + 1) {
            STORE(&q[idx], before);  /* untouched: the loaning reader keeps a valid message */
            return 0;
        }
    return 1;
}

/* Ring.commit: length and stamp, then what vouches for them, in order; then a full fence, so that
 * our head store comes before the caller reads the waiter table and who is spinning
 * (pubsub.Publisher: Dekker again). */
static void commit_slot(volatile unsigned long long *q, const geometry *g, Py_ssize_t idx, unsigned long long slot, unsigned long long n,
                        unsigned long long nbytes, unsigned long long stamp)
{
    STORE(&q[idx + 1], nbytes);
    STORE(&q[idx + 2], stamp);
    STORE_REL(&q[idx], 2 * n + 2);
    STORE_REL(&q[r_map + n % g->depth], (n << 16) | slot);
    STORE_REL(&q[r_head], n + 1);
    if (LOAD(&q[r_busy]))
        STORE(&q[r_busy], 0);
    FULL_FENCE();
}

/* The slot for message ``n``, claimed, as Ring.begin picks it: with ``recent``, the slot of
 * message n - 2 if every tracked reader has read past it (Ring._recent_slot), else the slot of
 * the message it retires (Ring._claim). Returns the slot's header index and sets ``*slot_out``,
 * or -1 with the ring untouched (Ring._claim_any's search, a damaged word: the Python path). */
static Py_ssize_t claim_next(volatile unsigned long long *q, const geometry *g, Py_ssize_t len, unsigned long long n, int recent,
                             unsigned long long *slot_out)
{
    if (recent && n >= 2 && g->depth > 2 && !LOAD(&q[r_untracked])) {
        int behind = 0;
        for (Py_ssize_t i = 0; i < r_max_waiters && !behind; i++)  /* the token before its cursor (add_waiter's order) */
            if (LOAD_ACQ(&q[r_waiters + i]) && LOAD(&q[r_cursors + i]) < n - 1)
                behind = 1;
        unsigned long long entry = LOAD(&q[r_map + (n - 2) % g->depth]), slot = entry & 0xFFFF;
        Py_ssize_t idx = behind || entry >> 16 != n - 2 ? -1 : slot_at(g, slot, g->capacity, len);
        if (idx >= 0 && LOAD(&q[idx]) == 2 * n - 2 && claim_slot(q, idx, slot, n, 0, 0)) {
            *slot_out = slot;
            return idx;
        }
    }
    unsigned long long entry = LOAD(&q[r_map + n % g->depth]), slot = entry & 0xFFFF;
    Py_ssize_t idx = slot_at(g, slot, g->capacity, len);
    if (idx < 0 || !claim_slot(q, idx, slot, n, 1, entry >> 16))
        return -1;
    *slot_out = slot;
    return idx;
}

/* ring_publish(msg, mm, depth, physical, data_offset, stride, capacity, stamp_ns, limit):
 * message ``msg`` written and committed as the ring's next message: returns its number. Or,
 * with the ring untouched: the codec.Encoded message (too big for ``limit`` or the slot, a slot
 * the fast path does not take: the caller goes the Python way with it), or NotImplemented
 * (the C encoder leaves the message to the Python codec). */
static PyObject *ring_publish(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    geometry g;
    unsigned long long stamp;
    if (ring_args("ring_publish(msg, mm, depth, physical, data_offset, stride, capacity, stamp_ns, limit)", args, nargs, 9, 2, &g, 7, 1, &stamp) < 0)
        return NULL;
    Py_ssize_t limit = PyLong_AsSsize_t(args[8]);
    if (limit == -1 && PyErr_Occurred())
        return NULL;

    PyObject *msg = args[0];
    encoder e = {.arrays = PyList_New(0), .offset = 0};
    if (e.arrays == NULL)
        return NULL;
    e.w.data = e.w.local;
    e.w.len = 0;
    e.w.cap = sizeof(e.w.local);
    PyObject *out = NULL;
    int r = put_message(&e, msg, (PyObject *)Py_TYPE(msg), 0);
    if (r != 0) {
        if (r == -2 && can_fall_back())
            out = Py_NewRef(Py_NotImplemented);
        goto done;
    }
    Py_ssize_t header = (4 + e.w.len + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
    Py_ssize_t nbytes = header + e.offset;
    Py_buffer buf;
    int written = 0;
    if (nbytes <= limit && (unsigned long long)nbytes <= g.capacity && e.w.len <= 0xFFFFFFFF) {
        if (PyObject_GetBuffer(args[1], &buf, PyBUF_WRITABLE) < 0)
            goto done;
        volatile unsigned long long *q = (volatile unsigned long long *)buf.buf;
        Py_ssize_t words = buf.len / 8;
        if (header_fits(&g, words)) {
            unsigned long long n = LOAD(&q[r_head]), slot = 0;
            Py_ssize_t idx = n < (unsigned long long)r_max_head ? claim_next(q, &g, buf.len, n, 0, &slot) : -1;
            if (idx >= 0) {
                char *dst = (char *)buf.buf + idx * 8 + r_slot_header;
                for (int b = 0; b < 4; b++)  /* u32 meta_len, little-endian as codec.py's frames */
                    dst[b] = (char)((e.w.len >> (8 * b)) & 0xFF);
                memcpy(dst + 4, e.w.data, e.w.len);
                memset(dst + 4 + e.w.len, 0, header - 4 - e.w.len);
                Py_ssize_t pos = header;
                for (Py_ssize_t i = 0; i < PyList_GET_SIZE(e.arrays); i++) {
                    PyArrayObject *arr = (PyArrayObject *)PyList_GET_ITEM(e.arrays, i);
                    Py_ssize_t an = PyArray_NBYTES(arr), padded = (an + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
                    memcpy(dst + pos, PyArray_DATA(arr), an);
                    memset(dst + pos + an, 0, padded - an);
                    pos += padded;
                }
                commit_slot(q, &g, idx, slot, n, (unsigned long long)nbytes, stamp);
                written = 1;
                out = PyLong_FromUnsignedLongLong(n);
            }
        }
        PyBuffer_Release(&buf);
    }
    if (!written) {
        PyObject *meta = PyBytes_FromStringAndSize(e.w.data, e.w.len);
        if (meta != NULL) {
            out = make_encoded(meta, e.arrays, e.offset);
            Py_DECREF(meta);
        }
    }
done:
    if (e.w.data != e.w.local)
        PyMem_Free(e.w.data);
    Py_DECREF(e.arrays);
    return out;
}

/* Bytes ring_write has copied with streaming stores, for tests and diagnostics (streamed()). */
static unsigned long long streamed_bytes;

static PyObject *streamed(PyObject *self, PyObject *unused)
{
    return PyLong_FromUnsignedLongLong(__atomic_load_n(&streamed_bytes, __ATOMIC_RELAXED));
}

/* ring_write(enc, mm, depth, physical, data_offset, stride, capacity, stamp_ns, recent_min, stream_min):
 * the encoded message ``enc`` (codec.Encoded) written and committed as the ring's next message,
 * fence included: returns its number. Or ``None`` with the ring untouched, for the Python path
 * (Ring.begin, Encoded.write_into, Ring.commit): a frame past the slot, an array that is not
 * C-contiguous, a slot Ring.begin must search for (Ring._claim_any), a damaged word.
 *
 * For big messages, which ring_publish leaves encoded: the announcement and early wake-up stay
 * in Python before this call (pubsub.Publisher._announce_write). ``recent_min``: a frame of that
 * many bytes or more may take the slot of message n - 2 (Ring.begin's ``recent``; 0: never).
 * ``stream_min``: arrays of that many bytes or more are copied with streaming stores
 * (codec.STREAM_MIN_BYTES). The GIL is released for the copy, as numpy's copy releases it. Why in
 * C: the Python path ran about 40 interpreter steps around a big copy (claim, announce, commit,
 * fence) on caches that copy had just flushed, 15-20 us at 8 MiB (docs/ipc.md, "Big messages"). */
static PyObject *ring_write(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    geometry g;
    unsigned long long vals[3];
    if (ring_args("ring_write(enc, mm, depth, physical, data_offset, stride, capacity, stamp_ns, recent_min, stream_min)", args, nargs, 10, 2, &g, 7, 3,
                  vals) < 0)
        return NULL;
    unsigned long long stamp = vals[0], recent_min = vals[1], stream_min = vals[2];
    PyObject *meta = PyObject_GetAttrString(args[0], "meta");
    PyObject *listed = meta == NULL ? NULL : PyObject_GetAttrString(args[0], "arrays");
    /* A tuple of our own: the list could change while the GIL is released for the copy. */
    PyObject *arrays = listed == NULL || !PyList_Check(listed) ? NULL : PyList_AsTuple(listed);
    Py_XDECREF(listed);
    PyObject *result = NULL;
    if (arrays == NULL || !PyBytes_Check(meta)) {
        if (PyErr_Occurred() && !PyErr_ExceptionMatches(PyExc_AttributeError))
            goto out;  /* out of memory, say: not ours to rename */
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "ring_write: enc must be a codec.Encoded (meta bytes, arrays list), got %.100s", Py_TYPE(args[0])->tp_name);
        goto out;
    }
    Py_ssize_t meta_len = PyBytes_GET_SIZE(meta);
    Py_ssize_t header = (4 + meta_len + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1), nbytes = header;
    Py_ssize_t count = PyTuple_GET_SIZE(arrays);
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *arr = PyTuple_GET_ITEM(arrays, i);
        if (!PyArray_Check(arr) || !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)arr)) {
            result = Py_NewRef(Py_None);
            goto out;
        }
        nbytes += (PyArray_NBYTES((PyArrayObject *)arr) + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
    }
    if ((unsigned long long)nbytes > g.capacity || meta_len > 0xFFFFFFFF) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    Py_buffer buf;
    if (PyObject_GetBuffer(args[1], &buf, PyBUF_WRITABLE) < 0)
        goto out;
    volatile unsigned long long *q = (volatile unsigned long long *)buf.buf;
    unsigned long long n = 0, slot = 0;
    Py_ssize_t idx = -1;
    if (header_fits(&g, buf.len / 8)) {
        n = LOAD(&q[r_head]);
        int recent = recent_min && (unsigned long long)nbytes >= recent_min;
        idx = n < (unsigned long long)r_max_head ? claim_next(q, &g, buf.len, n, recent, &slot) : -1;
    }
    if (idx < 0) {
        PyBuffer_Release(&buf);
        result = Py_NewRef(Py_None);
        goto out;
    }
    char *dst = (char *)buf.buf + idx * 8 + r_slot_header;
    const char *meta_bytes = PyBytes_AS_STRING(meta);
    Py_BEGIN_ALLOW_THREADS
    for (int b = 0; b < 4; b++)  /* u32 meta_len, little-endian as codec.py's frames */
        dst[b] = (char)((meta_len >> (8 * b)) & 0xFF);
    memcpy(dst + 4, meta_bytes, meta_len);
    memset(dst + 4 + meta_len, 0, header - 4 - meta_len);
    Py_ssize_t pos = header;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyArrayObject *arr = (PyArrayObject *)PyTuple_GET_ITEM(arrays, i);
        Py_ssize_t an = PyArray_NBYTES(arr), padded = (an + ALIGN - 1) & ~(Py_ssize_t)(ALIGN - 1);
        if (EMOS_STREAM_STORES && (unsigned long long)an >= stream_min) {
            copy_streaming(dst + pos, PyArray_DATA(arr), (size_t)an);
            __atomic_add_fetch(&streamed_bytes, (unsigned long long)an, __ATOMIC_RELAXED);
        } else
            memcpy(dst + pos, PyArray_DATA(arr), an);
        memset(dst + pos + an, 0, padded - an);
        pos += padded;
    }
    commit_slot(q, &g, idx, slot, n, (unsigned long long)nbytes, stamp);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&buf);
    result = PyLong_FromUnsignedLongLong(n);
out:
    Py_XDECREF(meta);
    Py_XDECREF(arrays);
    return result;
}

/* ring_take(mm, depth, physical, data_offset, stride, capacity, cursor, head, copy_max, out, publisher):
 * copies of the messages ``cursor``.. (before ``head``) appended to list ``out`` as
 * ``(stamp_ns, read-only memoryview, publisher)``, as Ring.read gives them; returns
 * ``(cursor, lapped)``: where it stopped (``head``, or the first message it leaves to the Python
 * path: not written yet, ``copy_max`` bytes or more, or not holding together) and how many
 * messages were overwritten before they could be read (LAPPED). */
static PyObject *ring_take(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    geometry g;
    unsigned long long vals[3];
    if (ring_args("ring_take(mm, depth, physical, data_offset, stride, capacity, cursor, head, copy_max, out, publisher)", args, nargs, 11, 1, &g, 6, 3,
                  vals) < 0)
        return NULL;
    unsigned long long cursor = vals[0], head = vals[1], copy_max = vals[2];
    PyObject *out = args[9], *publisher = args[10];
    if (!PyList_Check(out)) {
        PyErr_SetString(PyExc_TypeError, "ring_take: out must be a list");
        return NULL;
    }
    Py_buffer buf;
    if (PyObject_GetBuffer(args[0], &buf, PyBUF_SIMPLE) < 0)
        return NULL;
    const volatile unsigned long long *q = (const volatile unsigned long long *)buf.buf;
    Py_ssize_t words = buf.len / 8;
    unsigned long long lapped = 0;
    int failed = 0;
    if (r_map + (Py_ssize_t)g.depth <= words && r_first < words) {
        while (cursor < head) {
            unsigned long long entry = LOAD_ACQ(&q[r_map + cursor % g.depth]);
            unsigned long long held = entry >> 16;
            if (held != cursor) {  /* Ring._locate */
                if (cursor >= LOAD(&q[r_first]) && (held == r_empty || held < cursor))
                    break;  /* not written yet */
                lapped++, cursor++;
                continue;
            }
            Py_ssize_t idx = slot_at(&g, entry & 0xFFFF, g.capacity, buf.len);
            if (idx < 0)
                break;  /* a slot outside the ring: the Python path says so (RingCorrupt) */
            unsigned long long want = 2 * cursor + 2;
            if (LOAD_ACQ(&q[idx]) != want) {
                lapped++, cursor++;  /* the slot was reused after we looked at the map */
                continue;
            }
            unsigned long long length = LOAD(&q[idx + 1]), stamp = LOAD(&q[idx + 2]);
            if (length > g.capacity || length >= copy_max)
                break;  /* damaged (if seq holds still) or big: the Python path reads or loans it */
            PyObject *copy = PyBytes_FromStringAndSize((const char *)buf.buf + idx * 8 + r_slot_header, (Py_ssize_t)length);
            if (copy == NULL) {
                failed = 1;
                break;
            }
            __atomic_thread_fence(__ATOMIC_ACQUIRE);  /* the copy before the second look at seq */
            if (LOAD(&q[idx]) != want) {
                Py_DECREF(copy);
                lapped++, cursor++;
                continue;
            }
            PyObject *view = PyMemoryView_FromObject(copy);  /* read-only: bytes are immutable */
            Py_DECREF(copy);
            PyObject *item = view == NULL ? NULL : Py_BuildValue("(KNO)", stamp, view, publisher);
            if (item == NULL || PyList_Append(out, item) < 0) {
                Py_XDECREF(item);
                failed = 1;
                break;
            }
            Py_DECREF(item);
            cursor++;
        }
    }
    PyBuffer_Release(&buf);
    if (failed)
        return NULL;
    return Py_BuildValue("(KK)", cursor, lapped);
}

/* ring_loan(mm, depth, physical, data_offset, stride, capacity, n, entry): message ``n``
 * pinned through pin ``entry`` and lent as a read-only uint8 view of its slot, as Ring.loan
 * does it: ``(OK, view, stamp_ns)``, or ``(NOT_READY | LAPPED, None, 0)`` with the entry free
 * again. ``None`` (the pin left free) for anything that does not hold together (a slot outside
 * the ring, a length past the slot, a pin entry out of range): Ring.loan then reads the words
 * again and raises its own error. Why in C: a big message's take ran about 20 interpreter
 * steps on caches the message's own copy had just flushed (8 us at 8 MiB; docs/ipc.md, "Big
 * messages: one C call each way").
 *
 * Protocol (ring.py's module doc): the pin store, a full fence (Dekker's handshake with a
 * writer claiming the slot, which stores seq odd, fences and then reads the pins), then seq must
 * be 2n+2; the view's memoryview holds a buffer export of ``mm``, so the mapping outlives the
 * ring's close for as long as the loan lives, as numpy.frombuffer's does. */
static PyObject *ring_loan(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    geometry g;
    unsigned long long vals[2];
    if (ring_args("ring_loan(mm, depth, physical, data_offset, stride, capacity, n, entry)", args, nargs, 8, 1, &g, 6, 2, vals) < 0)
        return NULL;
    unsigned long long n = vals[0], entry = vals[1];
    Py_buffer buf;
    if (PyObject_GetBuffer(args[0], &buf, PyBUF_WRITABLE) < 0)
        return NULL;
    volatile unsigned long long *q = (volatile unsigned long long *)buf.buf;
    Py_ssize_t words = buf.len / 8;
    PyObject *result = NULL;
    if (entry >= (unsigned long long)r_pins || r_pin + r_pins > words || r_map + (Py_ssize_t)g.depth > words || r_first >= words) {
        result = Py_NewRef(Py_None);
        goto done;
    }
    unsigned long long mapped = LOAD(&q[r_map + n % g.depth]), held = mapped >> 16;  /* Ring._locate */
    if (held != n) {
        int status = n < LOAD(&q[r_first]) ? 1 : (held == r_empty || held < n) ? 0 : 1;  /* LAPPED 1, NOT_READY 0 */
        result = Py_BuildValue("(iOi)", status, Py_None, 0);
        goto done;
    }
    unsigned long long slot = mapped & 0xFFFF;
    Py_ssize_t idx = slot_at(&g, slot, g.capacity, buf.len);
    if (idx < 0) {
        result = Py_NewRef(Py_None);  /* a slot outside the ring: Ring.loan raises RingCorrupt */
        goto done;
    }
    STORE(&q[r_pin + entry], slot + 1);
    FULL_FENCE();  /* the pin before we look at seq (a claiming writer fences, then reads pins) */
    unsigned long long seq = LOAD_ACQ(&q[idx]);
    unsigned long long length = LOAD(&q[idx + 1]), stamp = LOAD(&q[idx + 2]);
    if (seq != 2 * n + 2) {
        STORE(&q[r_pin + entry], 0);
        result = Py_BuildValue("(iOi)", 1, Py_None, 0);  /* LAPPED: reused since we looked */
        goto done;
    }
    if (length > g.capacity) {
        STORE(&q[r_pin + entry], 0);
        result = Py_NewRef(Py_None);  /* pinned and complete, so the writer did not write this */
        goto done;
    }
    PyObject *owner = PyMemoryView_FromObject(args[0]);  /* a buffer export: keeps the mapping */
    if (owner == NULL) {
        STORE(&q[r_pin + entry], 0);
        goto done;
    }
    npy_intp dims[1] = {(npy_intp)length};
    PyObject *view = PyArray_NewFromDescr(&PyArray_Type, PyArray_DescrFromType(NPY_UINT8), 1, dims, NULL,
                                          (char *)buf.buf + idx * 8 + r_slot_header, NPY_ARRAY_C_CONTIGUOUS | NPY_ARRAY_ALIGNED, NULL);
    if (view == NULL || PyArray_SetBaseObject((PyArrayObject *)view, owner) < 0) {  /* steals owner */
        if (view == NULL)
            Py_DECREF(owner);
        Py_XDECREF(view);
        STORE(&q[r_pin + entry], 0);
        goto done;
    }
    result = Py_BuildValue("(iNK)", 2, view, stamp);  /* OK */
    if (result == NULL)
        STORE(&q[r_pin + entry], 0);
done:
    PyBuffer_Release(&buf);
    return result;
}

/* ================================================================================== module */

static PyObject *setup(PyObject *self, PyObject *args)
{
    PyObject *enc_type, *slots, *hdrs, *hdr_fn, *builder, *py_encode, *py_decode;
    if (!PyArg_ParseTuple(args, "O!O!O!OOOO:setup", &PyType_Type, &enc_type, &PyTuple_Type, &slots, &PyDict_Type, &hdrs, &hdr_fn,
                          &builder, &py_encode, &py_decode))
        return NULL;
    if (PyTuple_GET_SIZE(slots) != 3) {
        PyErr_SetString(PyExc_ValueError, "setup: Encoded's slots are (meta, arrays, array_bytes)");
        return NULL;
    }
    Py_XSETREF(encoded_type, (PyTypeObject *)Py_NewRef(enc_type));
    Py_XSETREF(encoded_slots, Py_NewRef(slots));
    Py_XSETREF(headers_in, Py_NewRef(hdrs));
    Py_XSETREF(array_header, Py_NewRef(hdr_fn));
    Py_XSETREF(plan_builder, Py_NewRef(builder));
    Py_XSETREF(encode_python, Py_NewRef(py_encode));
    Py_XSETREF(decode_python, Py_NewRef(py_decode));
    PyDict_Clear(plans);
    Py_RETURN_NONE;
}

static PyObject *forget(PyObject *self, PyObject *unused)
{
    PyDict_Clear(plans);
    PyDict_Clear(dtype_strs);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"setup", setup, METH_VARARGS, "setup(Encoded, slots, headers_in, array_header, plan_builder, encode_python, decode_python)"},
    {"encode", encode, METH_O, "encode(msg) -> Encoded: the fast path, else codec.encode_python"},
    {"try_encode", try_encode, METH_O, "try_encode(msg) -> Encoded or NotImplemented (the fast path alone)"},
    {"decode", (PyCFunction)(void (*)(void))decode, METH_FASTCALL | METH_KEYWORDS,
     "decode(cls, frame, copy=False, arrays=None): the fast path, else codec.decode_python"},
    {"try_decode", (PyCFunction)(void (*)(void))try_decode, METH_FASTCALL | METH_KEYWORDS,
     "try_decode(cls, frame, copy=False, arrays=None) -> message or NotImplemented (the fast path alone)"},
    {"setup_frames", setup_frames, METH_VARARGS, "setup_frames(read_message_python, checked_names)"},
    {"frame_message", (PyCFunction)(void (*)(void))frame_message, METH_FASTCALL, "frame_message(msg, header, stamp_ns, limit) -> bytes or Encoded"},
    {"read_message", (PyCFunction)(void (*)(void))read_framed, METH_FASTCALL, "read_message(data, fingerprint, cls) -> (stamp_ns, publisher, message)"},
    {"try_read_message", (PyCFunction)(void (*)(void))try_read_message, METH_FASTCALL, "try_read_message(...) -> the tuple or NotImplemented"},
    {"forget", forget, METH_NOARGS, "forget(): drop the cached plans (after a message class changed, in tests)"},
    {"stream_copy", (PyCFunction)(void (*)(void))stream_copy, METH_FASTCALL,
     "stream_copy(dst, offset, src) -> end offset: src's bytes into dst at offset, with non-temporal stores and a store fence"},
    {"ring_layout", ring_layout, METH_VARARGS, "ring_layout(head, first, busy, map, pin, pins, slot_header, max_head, empty): ring.py's header layout"},
    {"ring_publish", (PyCFunction)(void (*)(void))ring_publish, METH_FASTCALL,
     "ring_publish(msg, mm, depth, physical, data_offset, stride, capacity, stamp_ns, limit) -> message number, or Encoded / NotImplemented (ring untouched)"},
    {"ring_loan", (PyCFunction)(void (*)(void))ring_loan, METH_FASTCALL,
     "ring_loan(mm, depth, physical, data_offset, stride, capacity, n, entry) -> (status, view, stamp_ns), or None (left to Ring.loan)"},
    {"streamed", streamed, METH_NOARGS, "streamed() -> bytes ring_write has copied with streaming stores in this process"},
    {"ring_write", (PyCFunction)(void (*)(void))ring_write, METH_FASTCALL,
     "ring_write(enc, mm, depth, physical, data_offset, stride, capacity, stamp_ns, recent_min, stream_min) -> message number, or None (ring untouched)"},
    {"ring_take", (PyCFunction)(void (*)(void))ring_take, METH_FASTCALL,
     "ring_take(mm, depth, physical, data_offset, stride, capacity, cursor, head, copy_max, out, publisher) -> (cursor, lapped)"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_ccodec", "The C fast path of emos.msgs.codec (see its source).", -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__ccodec(void)
{
    import_array();
    plans = PyDict_New();
    dtype_strs = PyDict_New();
    empty_tuple = PyTuple_New(0);
    if (plans == NULL || dtype_strs == NULL || empty_tuple == NULL)
        return NULL;
    PyObject *mod = PyModule_Create(&module);
    /* Whether stream_copy uses non-temporal stores here (else it is a plain memcpy). */
    if (mod != NULL && PyModule_AddIntConstant(mod, "STREAM_STORES", EMOS_STREAM_STORES) < 0)
        Py_CLEAR(mod);
    return mod;
}
