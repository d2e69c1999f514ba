/* Fused CPD E-step: one pass over the M source points per target point, no M x N array.
 *
 * estep(target, moved_t, n, m, d, sigma2, c, p1, pt1, px_t[, axis, halfwidth])
 *     -> sum_n log(den_n)
 *   target  : (N, D) float64 C-contiguous buffer
 *   moved_t : (D, M) float64 (the moved source, transposed: one row per coordinate)
 *   p1      : (M,) float64, accumulated (caller zeroes it)
 *   pt1     : (N,) float64, written
 *   px_t    : (D, M) float64, accumulated (caller zeroes it): (P X) transposed
 *   axis, halfwidth : optional truncation. When halfwidth > 0, moved_t must be sorted
 *             along row `axis`, and only source points with |t_axis - x_axis| <=
 *             halfwidth enter each target point's sums (the caller chooses halfwidth so
 *             that every dropped kernel value is below eps * c).
 *
 * The NumPy twin is posedrift.registration._estep.estep_numpy; tests compare them.
 * Uses the plain buffer protocol (no NumPy C API). The exponential is a
 * vectorizable Cody-Waite reduction with a degree-13 Taylor polynomial (relative
 * error ~1e-16 on the clamped range [-700, 0]).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static inline double fast_exp(double x) {
    /* x in [-700, 0] */
    const double log2e = 1.4426950408889634;
    const double ln2_hi = 6.93147180369123816490e-01;
    const double ln2_lo = 1.90821492927058770002e-10;
    const double shifter = 6755399441055744.0; /* 1.5 * 2^52 */
    double kd = x * log2e + shifter;
    uint64_t ki;
    memcpy(&ki, &kd, sizeof ki);
    kd -= shifter;
    double r = x - kd * ln2_hi - kd * ln2_lo;
    double p = 1.0 / 6227020800.0;
    p = p * r + 1.0 / 479001600.0;
    p = p * r + 1.0 / 39916800.0;
    p = p * r + 1.0 / 3628800.0;
    p = p * r + 1.0 / 362880.0;
    p = p * r + 1.0 / 40320.0;
    p = p * r + 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    uint64_t bits = (ki + 1023u) << 52;
    double scale;
    memcpy(&scale, &bits, sizeof scale);
    return p * scale;
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define MULTIVERSION __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define MULTIVERSION
#endif

MULTIVERSION
static double estep_kernel(const double *x, const double *mt, Py_ssize_t n, Py_ssize_t m,
                           Py_ssize_t d, double sigma2, double c, double *p1, double *pt1,
                           double *pxt, double *row, Py_ssize_t axis, double halfwidth) {
    const double a = -0.5 / sigma2;
    const double tiny = 2.2250738585072014e-308;
    double log_den = 0.0;
    const Py_ssize_t m_all = m;
    for (Py_ssize_t i = 0; i < n; ++i) {
        const double *xi = x + i * d;
        double s = 0.0;
        /* window: source points sorted along `axis`; only |t_axis - x_axis| <= halfwidth */
        Py_ssize_t lo = 0, hi = m_all;
        if (halfwidth > 0.0) {
            const double *ax = mt + axis * m_all;
            const double vlo = xi[axis] - halfwidth, vhi = xi[axis] + halfwidth;
            Py_ssize_t l = 0, h = m_all;
            while (l < h) { Py_ssize_t mid = (l + h) / 2; if (ax[mid] < vlo) l = mid + 1; else h = mid; }
            lo = l;
            h = m_all;
            while (l < h) { Py_ssize_t mid = (l + h) / 2; if (ax[mid] <= vhi) l = mid + 1; else h = mid; }
            hi = l;
        }
        m = hi - lo;
        const double *mw = mt + lo;
        double *p1w = p1 + lo;
        double *pxw = pxt + lo;
        if (d == 3) {
            const double x0 = xi[0], x1 = xi[1], x2 = xi[2];
            const double *m0 = mw, *m1 = mw + m_all, *m2 = mw + 2 * m_all;
#pragma omp simd reduction(+ : s)
            for (Py_ssize_t j = 0; j < m; ++j) {
                double e0 = x0 - m0[j], e1 = x1 - m1[j], e2 = x2 - m2[j];
                double z = a * (e0 * e0 + e1 * e1 + e2 * e2);
                z = z < -700.0 ? -700.0 : z;
                double k = fast_exp(z);
                row[j] = k;
                s += k;
            }
        } else {
            for (Py_ssize_t j = 0; j < m; ++j) row[j] = 0.0;
            for (Py_ssize_t k = 0; k < d; ++k) {
                const double xk = xi[k];
                const double *mk = mw + k * m_all;
                for (Py_ssize_t j = 0; j < m; ++j) {
                    double e = xk - mk[j];
                    row[j] += e * e;
                }
            }
#pragma omp simd reduction(+ : s)
            for (Py_ssize_t j = 0; j < m; ++j) {
                double z = a * row[j];
                z = z < -700.0 ? -700.0 : z;
                double k = fast_exp(z);
                row[j] = k;
                s += k;
            }
        }
        double den = s + c;
        if (!(den > tiny)) den = tiny;
        const double inv = 1.0 / den;
        pt1[i] = s * inv;
        log_den += log(den);
        for (Py_ssize_t j = 0; j < m; ++j) {
            double p = row[j] * inv;
            row[j] = p;
            p1w[j] += p;
        }
        for (Py_ssize_t k = 0; k < d; ++k) {
            const double xk = xi[k];
            double *pk = pxw + k * m_all;
            for (Py_ssize_t j = 0; j < m; ++j) pk[j] += row[j] * xk;
        }
    }
    return log_den;
}

static int check_buf(Py_buffer *b, Py_ssize_t count, const char *name) {
    if (b->len != (Py_ssize_t)(count * sizeof(double)) || b->itemsize != sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "_cestep.estep: buffer '%s' must hold %zd float64 values",
                     name, count);
        return -1;
    }
    return 0;
}

static PyObject *py_estep(PyObject *self, PyObject *args) {
    Py_buffer bx, bm, bp1, bpt1, bpx;
    Py_ssize_t n, m, d, axis = 0;
    double sigma2, c, halfwidth = 0.0;
    if (!PyArg_ParseTuple(args, "y*y*nnnddw*w*w*|nd", &bx, &bm, &n, &m, &d, &sigma2, &c, &bp1,
                          &bpt1, &bpx, &axis, &halfwidth))
        return NULL;
    PyObject *result = NULL;
    double *row = NULL;
    if (n < 1 || m < 1 || d < 1 || !(sigma2 > 0.0) || axis < 0 || axis >= d) {
        PyErr_SetString(PyExc_ValueError,
                        "_cestep.estep: need n, m, d >= 1, sigma2 > 0 and 0 <= axis < d");
        goto done;
    }
    if (check_buf(&bx, n * d, "target") || check_buf(&bm, m * d, "moved_t") ||
        check_buf(&bp1, m, "p1") || check_buf(&bpt1, n, "pt1") || check_buf(&bpx, m * d, "px_t"))
        goto done;
    row = (double *)malloc((size_t)m * sizeof(double));
    if (!row) {
        PyErr_NoMemory();
        goto done;
    }
    double log_den;
    Py_BEGIN_ALLOW_THREADS
    log_den = estep_kernel((const double *)bx.buf, (const double *)bm.buf, n, m, d, sigma2, c,
                           (double *)bp1.buf, (double *)bpt1.buf, (double *)bpx.buf, row, axis,
                           halfwidth);
    Py_END_ALLOW_THREADS
    result = PyFloat_FromDouble(log_den);
done:
    free(row);
    PyBuffer_Release(&bx);
    PyBuffer_Release(&bm);
    PyBuffer_Release(&bp1);
    PyBuffer_Release(&bpt1);
    PyBuffer_Release(&bpx);
    return result;
}

static PyMethodDef methods[] = {
    {"estep", py_estep, METH_VARARGS,
     "estep(target, moved_t, n, m, d, sigma2, c, p1, pt1, px_t[, axis, halfwidth]) -> sum log den"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cestep",
                                    "Fused CPD E-step (float64).", -1, methods};

PyMODINIT_FUNC PyInit__cestep(void) { return PyModule_Create(&module); }
