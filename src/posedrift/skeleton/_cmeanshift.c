/* Compiled kernel of posedrift.skeleton: grouped Gaussian mean shift.
 *
 * shift(coords, group, weight, centre, live, scale, max_iter, tol, min_mass, drop_lost)
 *   -> number of steps taken
 *   Every group's centre climbs the kernel density of its own points, all groups in one
 *   sweep per step: m_g <- sum_i k_i p_i / sum_i k_i over the points i of group g, with
 *   k_i = weight_i * exp(scale * |p_i - m_g|^2) (scale = -1 / (2 bandwidth^2)).
 *   coords    : (M, 3) float64, the points
 *   group     : (M,) int64, each point's group in [0, G); others are skipped
 *   weight    : (M,) float64, non-negative
 *   centre    : (G, 3) float64, the starting centres; written with the modes
 *   live      : (G,) uint8, the groups that climb; written (see drop_lost)
 *   A group whose kernel mass falls to min_mass or below stays where it is, or with
 *   drop_lost is dropped from live. The climb stops after max_iter steps, when no group
 *   moved, or when no centre moved more than tol (max-norm, metres) in a step.
 *
 * The twin is skeleton._meanshift._shift_modes_numpy (tests/test_meanshift.py compares
 * them): the same sums in the same order (per group, points in input order); exp may
 * differ from NumPy's in the last bit. Plain buffer protocol (no NumPy C API).
 */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("fp-contract=off")
#endif
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static PyObject *shift(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *objs[5];
    double scale, tol, min_mass;
    Py_ssize_t max_iter;
    int drop_lost;
    if (!PyArg_ParseTuple(args, "OOOOOdnddp", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &scale, &max_iter, &tol, &min_mass, &drop_lost))
        return NULL;
    static const Py_ssize_t itemsize[5] = {8, 8, 8, 8, 1};
    Py_buffer b[5];
    int got = 0;
    for (; got < 5; got++) {
        int flags = PyBUF_C_CONTIGUOUS | (got >= 3 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(objs[got], &b[got], flags) < 0) break;
        if (b[got].itemsize != itemsize[got]) {
            PyBuffer_Release(&b[got]);
            PyErr_SetString(PyExc_ValueError, "shift: a buffer has the wrong item size");
            break;
        }
    }
    if (got < 5) {
        for (int i = 0; i < got; i++) PyBuffer_Release(&b[i]);
        return NULL;
    }
    const Py_ssize_t m = b[1].len / 8, g_count = b[4].len;
    if (b[0].len != 24 * m || b[2].len != 8 * m || b[3].len != 24 * g_count) {
        for (int i = 0; i < 5; i++) PyBuffer_Release(&b[i]);
        PyErr_SetString(PyExc_ValueError, "shift: inconsistent buffer lengths");
        return NULL;
    }
    double *sums = malloc(sizeof(double) * 4 * (size_t)(g_count > 0 ? g_count : 1));
    if (sums == NULL) {
        for (int i = 0; i < 5; i++) PyBuffer_Release(&b[i]);
        return PyErr_NoMemory();
    }
    const double *p = (const double *)b[0].buf, *w = (const double *)b[2].buf;
    const int64_t *group = (const int64_t *)b[1].buf;
    double *centre = (double *)b[3].buf;
    uint8_t *live = (uint8_t *)b[4].buf;
    Py_ssize_t step = 0;
    Py_BEGIN_ALLOW_THREADS
    while (step < max_iter) {
        step++;
        memset(sums, 0, sizeof(double) * 4 * (size_t)g_count);
        for (Py_ssize_t i = 0; i < m; i++) {
            const int64_t g = group[i];
            if (g < 0 || g >= g_count || !live[g]) continue;
            const double *c = centre + 3 * g, *q = p + 3 * i;
            const double dx = q[0] - c[0], dy = q[1] - c[1], dz = q[2] - c[2];
            double r2 = dx * dx + dy * dy;
            r2 += dz * dz;
            const double k = w[i] * exp(scale * r2);
            double *s = sums + 4 * g;
            s[0] += k;
            s[1] += q[0] * k;
            s[2] += q[1] * k;
            s[3] += q[2] * k;
        }
        double moved = 0.0;
        int any = 0;
        for (Py_ssize_t g = 0; g < g_count; g++) {
            if (!live[g]) continue;
            const double *s = sums + 4 * g;
            if (!(s[0] > min_mass)) {
                if (drop_lost) live[g] = 0;
                continue;
            }
            any = 1;
            for (int d = 0; d < 3; d++) {
                const double next = s[1 + d] / s[0];
                const double change = fabs(next - centre[3 * g + d]);
                if (change > moved) moved = change;
                centre[3 * g + d] = next;
            }
        }
        if (!any || moved < tol) break;
    }
    Py_END_ALLOW_THREADS
    free(sums);
    for (int i = 0; i < 5; i++) PyBuffer_Release(&b[i]);
    return PyLong_FromSsize_t(step);
}

static PyMethodDef methods[] = {
    {"shift", shift, METH_VARARGS,
     "shift(coords, group, weight, centre, live, scale, max_iter, tol, min_mass, drop_lost) "
     "-> steps: grouped Gaussian mean shift."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cmeanshift", "Compiled mean shift of posedrift.skeleton.", -1,
    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__cmeanshift(void) { return PyModule_Create(&module); }
