/* The swept-footprint check's inner loop in C: SweptFootprint._touches (swept.py), the same
 * answers.
 *
 * Why it exists: the check runs for every command the DriveManager sends (issue 38's goal: p99 <=
 * 1 ms on one core). In numpy, a command that touches needs two batches (the command, then the
 * stop and the slower versions), and each batch is some thirty array operations on small arrays:
 * per operation a few microseconds of numpy's fixed cost, and temporaries of up to a megabyte
 * (candidates x gains x poses x points) written and read again. Here one pass per pose over the
 * points keeps four running minima per point in registers and cache.
 *
 * It follows the Python version step by step (the coarse prefilter, the spans, the early end of a
 * batch once its decisive candidate touches), so that it decides exactly as it does and reports
 * the same clearance to rounding: tests/safety_swept/test_swept_same_decisions.py runs the
 * recorded cases through both. The only differences are the order of floating-point operations
 * inside a dot product (numpy hands those to BLAS), a few units in the last place.
 *
 * The inputs come from SweptFootprint (our own process), not from a peer: the arrays are checked
 * for their shapes so that nothing is read outside them, and points are finite (prepare() drops
 * the others).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#define MAX_PARTS 64

static inline double dmin(double a, double b) { return b < a ? b : a; }
static inline double dmax(double a, double b) { return b > a ? b : a; }

/* The footprint and the constants of swept.py, given by the caller (one home for each). */
typedef struct {
    int box;           /* 1: the box's exact distance; 0: the bounding circle's */
    double half_x;     /* the box's half extents (m) */
    double half_y;
    double radius;     /* the bounding radius the prefilter uses (m) */
    double margin;     /* SweptConfig.margin (m) */
    Py_ssize_t stride; /* _COARSE_STRIDE: the prefilter looks at every stride-th pose's centre */
    Py_ssize_t parts;  /* _PARTS: after the shared poses, the rest in this many spans */
    double tol;        /* _TOL (m): a point must come this much nearer than it started */
} Shape;

/* A C-contiguous float64 view of obj with ndim dimensions (a copy only when obj is not one). */
static PyArrayObject *as_array(PyObject *obj, int ndim, const char *name)
{
    PyArrayObject *arr = (PyArrayObject *)PyArray_FROMANY(obj, NPY_DOUBLE, ndim, ndim, NPY_ARRAY_IN_ARRAY);
    if (arr == NULL && PyErr_ExceptionMatches(PyExc_ValueError)) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "_cswept.touches: %s must be a %d-d float array", name, ndim);
    }
    return arr;
}

/* Per point of one span, over the span's poses of one candidate (all gains), running minima
 * over the first `head` poses (h) and over the rest (t). For the box, as
 * SweptFootprint._least_distance's box branch: q = |body| - half, the least depth max(qx, qy)
 * and the least squared distance outside max(qx, 0)^2 + max(qy, 0)^2 (out_*); for the bounding
 * circle, the least hypot(body) - radius (in depth_*, out_* unused). */
static void span_minima(const double *poses, Py_ssize_t n_g, Py_ssize_t k1, Py_ssize_t p0, Py_ssize_t p1,
                        Py_ssize_t head, const double *px, const double *py, Py_ssize_t m, const Shape *shape,
                        double *depth_h, double *out_h, double *depth_t, double *out_t)
{
    const double hx = shape->half_x, hy = shape->half_y, radius = shape->radius;
    for (Py_ssize_t g = 0; g < n_g; g++) {
        for (Py_ssize_t p = p0; p < p1; p++) {
            /* The pose's frame: a point's body x = c px + s py + tx, y = -s px + c py + ty. */
            const double *pose = poses + 3 * (g * k1 + p);
            const double c = cos(pose[2]), s = sin(pose[2]);
            const double tx = -(c * pose[0] + s * pose[1]), ty = s * pose[0] - c * pose[1];
            double *depth = p - p0 < head ? depth_h : depth_t;
            double *out = p - p0 < head ? out_h : out_t;
            if (shape->box) {
                for (Py_ssize_t n = 0; n < m; n++) {
                    const double bx = c * px[n] + s * py[n] + tx;
                    const double by = -s * px[n] + c * py[n] + ty;
                    const double qx = fabs(bx) - hx, qy = fabs(by) - hy;
                    const double ox = dmax(qx, 0.0), oy = dmax(qy, 0.0);
                    depth[n] = dmin(depth[n], dmax(qx, qy));
                    out[n] = dmin(out[n], ox * ox + oy * oy);
                }
            } else {
                for (Py_ssize_t n = 0; n < m; n++) {
                    const double bx = c * px[n] + s * py[n] + tx;
                    const double by = -s * px[n] + c * py[n] + ty;
                    depth[n] = dmin(depth[n], hypot(bx, by) - radius);
                }
            }
        }
    }
}

/* The signed distance from a least depth and a least squared distance outside (swept._signed). */
static inline double signed_distance(double depth, double out) { return sqrt(out) + dmin(depth, 0.0); }

/* touches(poses, homog, norm2, start, limits, steps, shared, shared_limit, decisive, shape)
 * -> list per candidate of None or (touches, clearance beyond the margin, a touch within
 * shared_limit at one of the first shared + 1 poses, those poses clear within the limit).
 * SweptFootprint._touches says what each means; decisive < 0: none. */
static PyObject *touches(PyObject *self, PyObject *args)
{
    PyObject *poses_obj, *homog_obj, *norm2_obj, *start_obj, *limits_obj, *steps_obj;
    Py_ssize_t shared, decisive;
    double shared_limit;
    Shape sh;
    if (!PyArg_ParseTuple(args, "OOOOOOndn(iddddnnd)", &poses_obj, &homog_obj, &norm2_obj, &start_obj, &limits_obj,
                          &steps_obj, &shared, &shared_limit, &decisive, &sh.box, &sh.half_x, &sh.half_y, &sh.radius,
                          &sh.margin, &sh.stride, &sh.parts, &sh.tol))
        return NULL;
    if (sh.stride < 1 || sh.parts < 1 || sh.parts > MAX_PARTS) {
        PyErr_SetString(PyExc_ValueError, "_cswept.touches: expected stride >= 1 and parts in 1..64");
        return NULL;
    }
    PyArrayObject *poses_a = NULL, *homog_a = NULL, *norm2_a = NULL, *start_a = NULL, *limits_a = NULL, *steps_a = NULL;
    PyObject *result = NULL;
    unsigned char *close = NULL, *near = NULL, *flags = NULL;
    double *work = NULL;
    Py_ssize_t *cand = NULL;

    if (!(poses_a = as_array(poses_obj, 4, "poses")) || !(homog_a = as_array(homog_obj, 2, "homog")) ||
        !(norm2_a = as_array(norm2_obj, 1, "norm2")) || !(start_a = as_array(start_obj, 1, "start")) ||
        !(limits_a = as_array(limits_obj, 1, "limits")) || !(steps_a = as_array(steps_obj, 1, "steps")))
        goto done;
    const Py_ssize_t n_c = PyArray_DIM(poses_a, 0), n_g = PyArray_DIM(poses_a, 1), k1 = PyArray_DIM(poses_a, 2);
    const Py_ssize_t n_pts = PyArray_DIM(homog_a, 1);
    if (PyArray_DIM(poses_a, 3) != 3 || PyArray_DIM(homog_a, 0) != 3 || PyArray_DIM(norm2_a, 0) != n_pts ||
        PyArray_DIM(start_a, 0) != n_pts || PyArray_DIM(limits_a, 0) != n_c || PyArray_DIM(steps_a, 0) != n_c ||
        (decisive >= n_c)) {
        PyErr_SetString(PyExc_ValueError, "_cswept.touches: expected poses (C, G, K, 3), homog (3, N), norm2 and start (N,), "
                                          "limits and steps (C,), decisive < C");
        goto done;
    }
    const double *poses = PyArray_DATA(poses_a), *homog = PyArray_DATA(homog_a), *norm2 = PyArray_DATA(norm2_a);
    const double *start = PyArray_DATA(start_a), *limits = PyArray_DATA(limits_a), *steps = PyArray_DATA(steps_a);
    const double *hx_row = homog, *hy_row = homog + n_pts;
    if (!(result = PyList_New(n_c)))
        goto done;
    for (Py_ssize_t c = 0; c < n_c; c++) {
        Py_INCREF(Py_None);
        PyList_SET_ITEM(result, c, Py_None);
    }
    if (n_c == 0 || n_g == 0 || k1 == 0 || n_pts == 0)
        goto done;

    /* The prefilter: close[c, j, n], point n within R + limit + travel of coarse pose j's centre
     * for some gain (squared distance less |p|^2, as (-2 cx, -2 cy, |c|^2) . (px, py, 1)). */
    const Py_ssize_t stride = sh.stride, n_j = (k1 + stride - 1) / stride;
    close = calloc((size_t)(n_c * n_j * n_pts), 1);
    near = calloc((size_t)n_c, 1);
    flags = calloc((size_t)(3 * n_c), 1);
    /* work: the least d2 over gains (N), then per span the gathered points and minima. */
    work = malloc(sizeof(double) * (size_t)(n_pts * (3 + 6 * n_c) + 4 * n_c));
    cand = malloc(sizeof(Py_ssize_t) * (size_t)n_pts);
    if (!close || !near || !flags || !work || !cand) {
        PyErr_NoMemory();
        Py_CLEAR(result);
        goto done;
    }
    int any_near = 0;
    double *best = work;
    for (Py_ssize_t c = 0; c < n_c; c++) {
        const double r = sh.radius + limits[c] + steps[c], r2 = r * r;
        for (Py_ssize_t j = 0; j < n_j; j++) {
            for (Py_ssize_t n = 0; n < n_pts; n++)
                best[n] = INFINITY;
            for (Py_ssize_t g = 0; g < n_g; g++) {
                const double *centre = poses + 3 * ((c * n_g + g) * k1 + j * stride);
                const double ax = -2.0 * centre[0], ay = -2.0 * centre[1];
                const double cc = centre[0] * centre[0] + centre[1] * centre[1];
                for (Py_ssize_t n = 0; n < n_pts; n++)
                    best[n] = dmin(best[n], ax * hx_row[n] + ay * hy_row[n] + cc);
            }
            unsigned char *row = close + (c * n_j + j) * n_pts;
            for (Py_ssize_t n = 0; n < n_pts; n++) {
                row[n] = best[n] <= r2 - norm2[n];
                near[c] |= row[n];
            }
        }
        any_near |= near[c];
    }
    if (!any_near)
        goto done;

    /* Spans of coarse poses: the shared ones (the pipe), then the rest in `parts` spans. */
    Py_ssize_t cut = (shared > 0 ? shared : 0) / stride + 1;
    if (cut > n_j)
        cut = n_j;
    Py_ssize_t edges[MAX_PARTS + 2];
    edges[0] = 0;
    for (Py_ssize_t i = 0; i <= sh.parts; i++)
        edges[i + 1] = cut + ((n_j - cut) * i + sh.parts - 1) / sh.parts;

    double *px = work + n_pts, *py = px + n_pts, *acc = py + n_pts;  /* acc: 6 x (C, N) minima */
    double *low = acc + 6 * n_c * n_pts;                               /* (C,) */
    unsigned char *hit = flags, *early = flags + n_c, *head_hit = flags + 2 * n_c;
    for (Py_ssize_t c = 0; c < n_c; c++)
        low[c] = INFINITY;
    for (Py_ssize_t e = 0; e <= sh.parts; e++) {
        const Py_ssize_t a = edges[e], b = edges[e + 1];
        if (b <= a)
            continue;
        /* The points near any of the span's coarse poses, of any candidate and gain. */
        Py_ssize_t m = 0;
        for (Py_ssize_t n = 0; n < n_pts; n++) {
            unsigned char any = 0;
            for (Py_ssize_t c = 0; c < n_c && !any; c++)
                for (Py_ssize_t j = a; j < b && !any; j++)
                    any = close[(c * n_j + j) * n_pts + n];
            if (any) {
                cand[m] = n;
                px[m] = hx_row[n];
                py[m] = hy_row[n];
                m++;
            }
        }
        if (m == 0)
            continue;
        const Py_ssize_t head = (a == 0 && shared >= 0) ? shared + 1 : 0;
        const Py_ssize_t p0 = a * stride, p1 = b * stride < k1 ? b * stride : k1;
        for (Py_ssize_t c = 0; c < n_c; c++) {
            double *depth_h = acc + 6 * c * n_pts, *out_h = depth_h + n_pts;
            double *depth_t = out_h + n_pts, *out_t = depth_t + n_pts;
            double *least = out_t + n_pts, *least_head = least + n_pts;
            for (Py_ssize_t n = 0; n < m; n++)
                depth_h[n] = out_h[n] = depth_t[n] = out_t[n] = INFINITY;
            const double *cposes = poses + 3 * c * n_g * k1;
            span_minima(cposes, n_g, k1, p0, p1, head, px, py, m, &sh, depth_h, out_h, depth_t, out_t);
            if (sh.box) {
                for (Py_ssize_t n = 0; n < m; n++) {
                    least_head[n] = signed_distance(depth_h[n], out_h[n]);
                    least[n] = signed_distance(dmin(depth_h[n], depth_t[n]), dmin(out_h[n], out_t[n]));
                }
            } else {
                for (Py_ssize_t n = 0; n < m; n++) {
                    least_head[n] = depth_h[n];
                    least[n] = dmin(depth_h[n], depth_t[n]);
                }
            }
            /* Touching: within the limit and nearer than the point started. */
            double span_low = INFINITY;
            unsigned char span_hit = 0, span_early = 0, span_head_hit = 0;
            const double early_limit = shared_limit;
            for (Py_ssize_t n = 0; n < m; n++) {
                const double begin = start[cand[n]] - sh.tol;
                const double threshold = dmin(limits[c], begin);
                span_low = dmin(span_low, least[n]);
                span_hit |= least[n] < threshold;
                if (head) {
                    span_early |= least_head[n] < dmin(early_limit, begin);
                    span_head_hit |= least_head[n] < threshold;
                }
            }
            low[c] = dmin(low[c], span_low);
            hit[c] |= span_hit;
            if (head) {
                early[c] = span_early;
                head_hit[c] = span_head_hit;
            }
        }
        int all_hit = 1;
        for (Py_ssize_t c = 0; c < n_c; c++)
            all_hit &= hit[c];
        if (all_hit || (decisive >= 0 && hit[decisive]))
            break;
    }
    for (Py_ssize_t c = 0; c < n_c; c++) {
        if (!near[c])
            continue;
        const double clearance = low[c] - limits[c] + sh.margin;
        const int head_clear = shared >= 0 ? !head_hit[c] : 0;
        PyObject *item = Py_BuildValue("(NdNN)", PyBool_FromLong(hit[c]), clearance, PyBool_FromLong(early[c]),
                                       PyBool_FromLong(head_clear));
        if (item == NULL) {
            Py_CLEAR(result);
            goto done;
        }
        PyList_SetItem(result, c, item); /* drops the None */
    }

done:
    free(close);
    free(near);
    free(flags);
    free(work);
    free(cand);
    Py_XDECREF(poses_a);
    Py_XDECREF(homog_a);
    Py_XDECREF(norm2_a);
    Py_XDECREF(start_a);
    Py_XDECREF(limits_a);
    Py_XDECREF(steps_a);
    return result;
}

static PyMethodDef methods[] = {
    {"touches", touches, METH_VARARGS, "SweptFootprint._touches in C (swept.py): the same answers."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cswept", "The swept-footprint check's inner loop in C.", -1, methods};

PyMODINIT_FUNC PyInit__cswept(void)
{
    import_array();
    return PyModule_Create(&module);
}
