/* Compiled kernels of posedrift.points: the person segmentation's connected components
 * and the downsampling's voxel centroids.
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
 *
 * voxel_centroids(points, n, size, centroids, inverse) -> count
 *   points._downsample._voxel_centroids: the centroid of the points in each occupied cell
 *   of a grid of `size` from the points' lowest corner, cells in increasing flat index
 *   (as np.unique orders them), each centroid summing its points in input order then
 *   dividing by their count (as np.bincount does).
 *   points : (n, 3) float64, n >= 1; centroids: (n, 3) float64, written in its first count
 *            rows; inverse: (n,) int64, written: each point's cell
 *
 * The twins are the NumPy and scipy.ndimage code of _components and the NumPy code of
 * _voxel_centroids; tests/test_segment.py compares them. Plain buffer protocol (no NumPy C API). No -ffast-math: the float32
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
#include <string.h>

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

typedef struct {
    int64_t key;
    int64_t idx;
} keyed_cell;

static int cmp_cell(const void *pa, const void *pb) {
    const keyed_cell *a = (const keyed_cell *)pa, *b = (const keyed_cell *)pb;
    if (a->key != b->key) return a->key < b->key ? -1 : 1;
    return (a->idx > b->idx) - (a->idx < b->idx);
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define MULTIVERSION __attribute__((target_clones("avx2", "default")))
#else
#define MULTIVERSION
#endif

/* flat (n): each point's cell (k0 d1 + k1) d2 + k2 with k = floor((p - lowest) / size),
 * dims (3): the grid's extent. Cloned for AVX2, where floor is one instruction. */
MULTIVERSION
static void cell_keys(const double *p, Py_ssize_t n, double size, int64_t *flat,
                      int64_t dims[3]) {
    double low[3];
    for (int d = 0; d < 3; d++) {
        low[d] = p[d];
        for (Py_ssize_t i = 1; i < n; i++) low[d] = p[3 * i + d] < low[d] ? p[3 * i + d] : low[d];
        dims[d] = 0;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t key[3];
        for (int d = 0; d < 3; d++) {
            key[d] = (int64_t)floor((p[3 * i + d] - low[d]) / size);
            if (key[d] + 1 > dims[d]) dims[d] = key[d] + 1;
        }
        flat[3 * i] = key[0];
        flat[3 * i + 1] = key[1];
        flat[3 * i + 2] = key[2];
    }
    for (Py_ssize_t i = 0; i < n; i++)
        flat[i] = (flat[3 * i] * dims[1] + flat[3 * i + 1]) * dims[2] + flat[3 * i + 2];
}

static PyObject *voxel_centroids(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *o_points, *o_cent, *o_inv;
    Py_ssize_t n;
    double size;
    if (!PyArg_ParseTuple(args, "OndOO", &o_points, &n, &size, &o_cent, &o_inv)) return NULL;
    if (n < 1 || !(size > 0.0)) {
        PyErr_SetString(PyExc_ValueError, "voxel_centroids: need n >= 1 and size > 0");
        return NULL;
    }
    Py_buffer bp, bc, bi;
    if (get_buffer(o_points, &bp, 0, 8, 3 * n, "points") < 0) return NULL;
    if (get_buffer(o_cent, &bc, 1, 8, 3 * n, "centroids") < 0) {
        PyBuffer_Release(&bp);
        return NULL;
    }
    if (get_buffer(o_inv, &bi, 1, 8, n, "inverse") < 0) {
        PyBuffer_Release(&bp);
        PyBuffer_Release(&bc);
        return NULL;
    }
    const double *p = (const double *)bp.buf;
    double *cent = (double *)bc.buf;
    int64_t *inv = (int64_t *)bi.buf;
    int64_t *flat = (int64_t *)malloc(sizeof(int64_t) * (size_t)(3 * n)); /* keys, then cells */
    int64_t *counts = NULL, *rank = NULL;
    keyed_cell *sorted = NULL;
    Py_ssize_t k = -1;
    if (flat == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    int64_t dims[3];
    cell_keys(p, n, size, flat, dims);
    const int64_t cells = dims[0] * dims[1] * dims[2];
    if (cells <= 16 * (int64_t)n + 4096) { /* occupancy by counting over the grid */
        counts = (int64_t *)calloc((size_t)cells, sizeof(int64_t));
        rank = (int64_t *)malloc(sizeof(int64_t) * (size_t)cells);
        if (counts == NULL || rank == NULL) {
            PyErr_NoMemory();
            goto done;
        }
        for (Py_ssize_t i = 0; i < n; i++) counts[flat[i]]++;
        k = 0;
        for (int64_t c = 0; c < cells; c++)
            if (counts[c]) rank[c] = k++;
        for (Py_ssize_t i = 0; i < n; i++) inv[i] = rank[flat[i]];
    } else { /* a sparse grid: sort the flat indices */
        sorted = (keyed_cell *)malloc(sizeof(keyed_cell) * (size_t)n);
        if (sorted == NULL) {
            PyErr_NoMemory();
            goto done;
        }
        for (Py_ssize_t i = 0; i < n; i++) {
            sorted[i].key = flat[i];
            sorted[i].idx = i;
        }
        qsort(sorted, (size_t)n, sizeof(keyed_cell), cmp_cell);
        k = 0;
        for (Py_ssize_t q = 0; q < n; q++) {
            if (q > 0 && sorted[q].key != sorted[q - 1].key) k++;
            inv[sorted[q].idx] = k;
        }
        k++;
    }
    /* Sums in input order, then one division by the count (np.bincount's weights). */
    memset(cent, 0, sizeof(double) * (size_t)(3 * k));
    int64_t *members = (int64_t *)calloc((size_t)k, sizeof(int64_t));
    if (members == NULL) {
        k = -1;
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        const int64_t c = inv[i];
        members[c]++;
        for (int d = 0; d < 3; d++) cent[3 * c + d] += p[3 * i + d];
    }
    for (int64_t c = 0; c < k; c++)
        for (int d = 0; d < 3; d++) cent[3 * c + d] /= (double)members[c];
    free(members);
done:
    free(flat);
    free(counts);
    free(rank);
    free(sorted);
    PyBuffer_Release(&bp);
    PyBuffer_Release(&bc);
    PyBuffer_Release(&bi);
    if (k < 0) return NULL;
    return PyLong_FromSsize_t((Py_ssize_t)k);
}

static PyMethodDef methods[] = {
    {"components", components, METH_VARARGS,
     "components(mask, depth, height, width, max_step, labels) -> count: the segmentation's "
     "connected components, cut at depth steps."},
    {"voxel_centroids", voxel_centroids, METH_VARARGS,
     "voxel_centroids(points, n, size, centroids, inverse) -> count: the downsampling's "
     "voxel centroids."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cpoints", "Compiled kernels of posedrift.points.", -1, methods,
    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__cpoints(void) { return PyModule_Create(&module); }
