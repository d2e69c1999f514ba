/* Compiled kernel of posedrift.points: the person segmentation's connected components.
 *
 * components(mask, depth, height, width, max_step, labels) -> count
 *   points._segment._components in one pass: 4-neighbour components of `mask` where a
 *   depth step between two kept neighbours cuts the farther pixel of the two.
 *   mask   : (height, width) uint8 (0 or 1), C-contiguous
 *   depth  : (height, width) float32; only the kept pixels' values are read
 *   max_step : metres; a step is |d_a - d_b| > max_step in float32, as NumPy compares
 *              a float32 array with a Python float
 *   labels : (height, width) int32, written: 0 for background and cut pixels, else
 *            1..count numbered in the raster order of each component's first pixel (as
 *            scipy.ndimage.label numbers them)
 *   Union-find over the raster scan, then one renumbering pass.
 * The twin is the NumPy and scipy.ndimage code of _components; tests/test_segment.py
 * compares them. Plain buffer protocol (no NumPy C API). No -ffast-math: the float32
 * comparisons must round as NumPy's do.
 */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("fp-contract=off")
#endif
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

static int get_buffer(PyObject *obj, Py_buffer *view, int writable, Py_ssize_t itemsize,
                      Py_ssize_t count, const char *name) {
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    if (view->itemsize != itemsize || view->len < itemsize * count) {
        PyErr_Format(PyExc_ValueError,
                     "components: buffer '%s' has the wrong size or item size", name);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static int32_t find(int32_t *parent, int32_t a) {
    while (parent[a] != a) {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    return a;
}

static void unite(int32_t *parent, int32_t a, int32_t b) {
    a = find(parent, a);
    b = find(parent, b);
    if (a < b) parent[b] = a;
    else if (b < a) parent[a] = b;
}

static PyObject *components(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *o_mask, *o_depth, *o_labels;
    Py_ssize_t h, w;
    double max_step_d;
    if (!PyArg_ParseTuple(args, "OOnndO", &o_mask, &o_depth, &h, &w, &max_step_d, &o_labels))
        return NULL;
    if (h < 0 || w < 0 || (w > 0 && h > INT32_MAX / w)) {
        PyErr_SetString(PyExc_ValueError, "components: bad image shape");
        return NULL;
    }
    const Py_ssize_t size = h * w;
    Py_buffer bm, bd, bl;
    if (get_buffer(o_mask, &bm, 0, 1, size, "mask") < 0) return NULL;
    if (get_buffer(o_depth, &bd, 0, 4, size, "depth") < 0) {
        PyBuffer_Release(&bm);
        return NULL;
    }
    if (get_buffer(o_labels, &bl, 1, 4, size, "labels") < 0) {
        PyBuffer_Release(&bm);
        PyBuffer_Release(&bd);
        return NULL;
    }
    const uint8_t *mask = (const uint8_t *)bm.buf;
    const float *depth = (const float *)bd.buf;
    int32_t *labels = (int32_t *)bl.buf;
    const float max_step = (float)max_step_d;
    uint8_t *core = (uint8_t *)malloc((size_t)(size > 0 ? size : 1));
    int32_t *parent = (int32_t *)malloc(sizeof(int32_t) * (size_t)(size + 1));
    Py_ssize_t count = -1;
    if (core == NULL || parent == NULL) {
        PyErr_NoMemory();
    } else {
        Py_BEGIN_ALLOW_THREADS
        /* A step between two kept 4-neighbours cuts the farther one (the nearer on a tie,
         * as the NumPy code's `d_b > d_a` test leaves it). */
        for (Py_ssize_t i = 0; i < size; i++) core[i] = mask[i] != 0;
        for (Py_ssize_t r = 0; r < h; r++) {
            for (Py_ssize_t c = 0; c < w; c++) {
                const Py_ssize_t a = r * w + c;
                if (!mask[a]) continue;
                const float da = depth[a];
                if (r + 1 < h && mask[a + w]) {
                    const float db = depth[a + w];
                    if (fabsf(db - da) > max_step) core[db > da ? a + w : a] = 0;
                }
                if (c + 1 < w && mask[a + 1]) {
                    const float db = depth[a + 1];
                    if (fabsf(db - da) > max_step) core[db > da ? a + 1 : a] = 0;
                }
            }
        }
        /* Union-find with each pixel its own provisional root, joined to its up and left
         * kept neighbours; roots are the smallest raster index of their component. */
        for (Py_ssize_t r = 0; r < h; r++) {
            for (Py_ssize_t c = 0; c < w; c++) {
                const Py_ssize_t a = r * w + c;
                if (!core[a]) continue;
                parent[a] = (int32_t)a;
                if (c > 0 && core[a - 1]) unite(parent, (int32_t)a, (int32_t)(a - 1));
                if (r > 0 && core[a - w]) unite(parent, (int32_t)a, (int32_t)(a - w));
            }
        }
        /* Renumber in raster order of the roots (each root is its component's first
         * pixel, so this is the order of first pixels). */
        int32_t next = 0;
        for (Py_ssize_t a = 0; a < size; a++) {
            if (!core[a]) {
                labels[a] = 0;
                continue;
            }
            const int32_t root = find(parent, (int32_t)a);
            if (root == a) {
                labels[a] = ++next;
            } else {
                labels[a] = labels[root];
            }
        }
        count = next;
        Py_END_ALLOW_THREADS
    }
    free(core);
    free(parent);
    PyBuffer_Release(&bm);
    PyBuffer_Release(&bd);
    PyBuffer_Release(&bl);
    if (count < 0) return NULL;
    return PyLong_FromSsize_t(count);
}

static PyMethodDef methods[] = {
    {"components", components, METH_VARARGS,
     "components(mask, depth, height, width, max_step, labels) -> count: the segmentation's "
     "connected components, cut at depth steps."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_csegment", "Compiled kernel of posedrift.points.", -1, methods,
    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__csegment(void) { return PyModule_Create(&module); }
