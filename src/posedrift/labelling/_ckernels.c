/* Compiled kernels of posedrift.labelling: the forest's descent and its joint votes,
 * relabelling's k-NN graph and geodesic distances.
 *
 * descend(table, image, rows, cols, row_scale, col_scale, roots, levels, height, width, out)
 *   The body-part forest's descent (BodyPartForest._descend_frame), every (tree, pixel)
 *   pair one level per sweep, so that the pairs' table reads overlap.
 *   table   : (M, 8) 32-bit records: float32 u_row, u_col, v_row, v_col, threshold, int32
 *             left, right, spare (a leaf: zero offsets, +inf threshold, itself twice)
 *   image   : ((H + 2) * (W + 2),) float32, the probe image (features.probe_image)
 *   rows, cols, row_scale, col_scale : (N,) float32, from features.pixel_terms
 *   roots   : (T,) int32; levels: sweeps (the deepest tree's depth); height, width: H, W
 *   out     : (T, N) int32, written: the node reached by each (tree, pixel)
 *   The same float32 operations in the same order as features.probe (no contraction into
 *   fused multiply-adds), so the same leaves as the NumPy descent.
 *
 * features(offsets, image, rows, cols, row_scale, col_scale, height, width, out)
 *   Every offset pair at every pixel (features.feature_matrix, the body-part net's input).
 *   offsets : (K, 4) float32 (u_row, u_col, v_row, v_col); image, rows, ...: as descend's
 *   out     : (N, K) float32, written: probe(u) - probe(v), the same float32 operations in
 *             the same order as features.probe, so the same values as the NumPy twin.
 *
 * cast(points, leaves, joint, offset, weight, wanted, where, joint_out, weight_out) -> M
 *   Every pixel's joint votes (JointVotes.cast), in the same order: tree, pixel, vote.
 *   points  : (N, 3) float64; leaves: (T, N) int32 leaf rows, -1 for none
 *   joint   : (L, K) int8 (-1 none); offset: (L, K, 3) float32; weight: (L, K) float32
 *   wanted  : (J,) uint8, the joints whose votes are cast
 *   where, joint_out, weight_out : (T * N * K, 3) float64, (T * N * K,) int64 and float64,
 *             written in their first M rows: point + offset, the joint, weight / T
 *
 * knn(points, n, k, dist, idx) -> None
 *   The k nearest points of every point, itself included (cKDTree(points).query(points, k)).
 *   points : (n, 3) float64, finite
 *   dist   : (n, k) float64, written: sqrt of ((dx^2 + dy^2) + dz^2), ascending
 *   idx    : (n, k) int64, written; ties in distance go to the lower index; where k > n
 *            the missing neighbours get +inf and index n (as cKDTree's)
 *   The same doubles as cKDTree's Euclidean query (squares summed over x, y, z in that
 *   order, one square root), found on a uniform grid ring of cells by ring of cells,
 *   until the next ring lies beyond the k-th best.
 *
 * graph_csr(points, n, kk, dist, idx, limit, depth_step, indptr, indices, data) -> nnz
 *   geodesic_graph's edges as a symmetric CSR matrix, from knn's (or cKDTree's) lists.
 *   dist, idx : (n, kk) float64 / int64, each point's kk nearest, the first column dropped
 *               (the point itself)
 *   An edge i-j is kept where its length is at most `limit`, j < n (a found neighbour),
 *   j != i, and, unless depth_step is NaN, not |z_j - z_i| > depth_step with
 *   |z_j - z_i| > hypot(x_j - x_i, y_j - y_i); lengths below 1e-9 become 1e-9.
 *   indptr : (n + 1,) int32; indices, data : (2 n (kk - 1),) int32 / float64, written
 *            in their first nnz entries: each row's columns ascending, every edge in
 *            both of its rows once (found from both ends, it has the same length)
 *
 * part_distances(points, n, anchors, n_anchors, k, labels, reach, indptr, indices, data, out)
 *   relabelling's _part_distances in one call: each anchor's source vertex (the nearest
 *   point carrying its part's label where the part has points, else the nearest point)
 *   and its Euclidean gap to it; then per part one Dijkstra search from all its anchors'
 *   sources at once, each starting at its gap, so that a point's distance is the smallest
 *   over the part's anchors of gap + path length. Binary heap with lazy deletion. Exact
 *   within the part's reach (plus 1e-9 and 1e-12 of it); the vertices beyond it only get
 *   the length of some path to them (breadth first), above the reach. Within the reach,
 *   the same doubles as scipy.sparse.csgraph.dijkstra from a vertex joined to the sources
 *   by edges of their gaps (_part_distances' NumPy code): a settled vertex's distance is
 *   the smallest fl(d(u) + w(u, v)) over its settled neighbours u, whatever the heap.
 *   points  : (n, 3) float64; anchors: (n_anchors, 3) float64, part j's k anchors in rows
 *             j k .. j k + k - 1, a NaN row for a missing one
 *   labels  : (n,) int64, or an empty buffer for none; reach: (n_anchors / k,) float64,
 *             or an empty buffer (or NaN) for exact distances everywhere
 *   indptr  : (n + 1,) int32; indices: (nnz,) int32; data: (nnz,) float64 non-negative:
 *             the graph in CSR (every edge stored in both of its rows)
 *   out     : (n_anchors / k, n) float64, written; inf for unreachable points and parts
 *             without anchors
 *
 * The twins are scipy's dijkstra and cKDTree, geodesic_graph's and _part_distances'
 * NumPy code, the NumPy descent and JointVotes.cast's NumPy path; tests/test_relabel.py,
 * tests/test_forest.py and tests/test_votes.py compare them. Plain buffer protocol (no
 * NumPy C API). Build with plain -O2/-O3: it relies on IEEE infinities and float32
 * rounding, so never with -ffast-math or -ffinite-math-only.
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

typedef struct {
    double key;
    int32_t node;
} item;

static inline void heap_push(item *heap, Py_ssize_t *size, double key, int32_t node) {
    Py_ssize_t i = (*size)++;
    while (i > 0) {
        Py_ssize_t parent = (i - 1) >> 1;
        if (heap[parent].key <= key) break;
        heap[i] = heap[parent];
        i = parent;
    }
    heap[i].key = key;
    heap[i].node = node;
}

static inline item heap_pop(item *heap, Py_ssize_t *size) {
    item top = heap[0];
    item last = heap[--(*size)];
    Py_ssize_t n = *size, i = 0;
    for (;;) {
        Py_ssize_t child = 2 * i + 1;
        if (child >= n) break;
        if (child + 1 < n && heap[child + 1].key < heap[child].key) child++;
        if (heap[child].key >= last.key) break;
        heap[i] = heap[child];
        i = child;
    }
    if (n > 0) heap[i] = last;
    return top;
}

static int get_buffer(PyObject *obj, Py_buffer *view, int writable, Py_ssize_t itemsize,
                      Py_ssize_t count, const char *name) {
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    if (view->itemsize != itemsize || view->len < itemsize * count) {
        PyErr_Format(PyExc_ValueError, "_ckernels: buffer '%s' has the wrong size or item size",
                     name);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* One Dijkstra search from several sources, each starting at its own distance, into dist
 * (n): exact within `limit`; beyond it a vertex only gets the length of some path to it
 * (breadth first), and unreachable ones +inf. heap: nnz + n_sources items, queue:
 * n + n_sources vertices of work space. */
static void dijkstra_run(const int32_t *indptr, const int32_t *indices, const double *data,
                         Py_ssize_t n, const int32_t *sources, const double *starts,
                         Py_ssize_t n_sources, double limit, double *dist, item *heap,
                         int32_t *queue) {
    for (Py_ssize_t v = 0; v < n; v++) dist[v] = INFINITY;
    Py_ssize_t size = 0, tail = 0;
    for (Py_ssize_t s = 0; s < n_sources; s++) {
        const int32_t v = sources[s];
        if (!(starts[s] < dist[v])) continue;
        dist[v] = starts[s];
        if (starts[s] <= limit)
            heap_push(heap, &size, starts[s], v);
        else
            queue[tail++] = v;
    }
    while (size > 0) {
        item top = heap_pop(heap, &size);
        if (top.key > dist[top.node]) continue; /* stale entry */
        const double d = top.key;
        for (int32_t e = indptr[top.node]; e < indptr[top.node + 1]; e++) {
            const int32_t v = indices[e];
            const double nd = d + data[e];
            if (nd <= limit) {
                if (nd < dist[v]) {
                    dist[v] = nd;
                    heap_push(heap, &size, nd, v);
                }
            } else if (dist[v] == INFINITY) {
                dist[v] = nd; /* beyond the limit: reachable, not exact */
                queue[tail++] = v;
            }
        }
    }
    /* Breadth first over the rest: any path length, all above the limit. */
    for (Py_ssize_t head = 0; head < tail; head++) {
        const int32_t u = queue[head];
        if (!(dist[u] > limit)) continue; /* lowered within the limit since */
        for (int32_t e = indptr[u]; e < indptr[u + 1]; e++) {
            const int32_t v = indices[e];
            if (dist[v] == INFINITY) {
                dist[v] = dist[u] + data[e];
                queue[tail++] = v;
            }
        }
    }
}

static PyObject *descend(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *objs[8];
    Py_ssize_t levels, height, width;
    if (!PyArg_ParseTuple(args, "OOOOOOOnnnO", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &levels, &height, &width, &objs[7]))
        return NULL;
    Py_buffer b[8];
    int got = 0;
    for (; got < 8; got++) {
        int flags = PyBUF_C_CONTIGUOUS | (got == 7 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(objs[got], &b[got], flags) < 0) break;
        if (b[got].itemsize != 4) {
            PyBuffer_Release(&b[got]);
            PyErr_SetString(PyExc_ValueError, "descend: every buffer must hold 32-bit items");
            break;
        }
    }
    if (got < 8) {
        for (int i = 0; i < got; i++) PyBuffer_Release(&b[i]);
        return NULL;
    }
    const Py_ssize_t n_nodes = b[0].len / 32;
    const Py_ssize_t n = b[2].len / 4;
    const Py_ssize_t n_trees = b[6].len / 4;
    const int32_t *table = (const int32_t *)b[0].buf;
    const float *image = (const float *)b[1].buf;
    const float *rows = (const float *)b[2].buf, *cols = (const float *)b[3].buf;
    const float *row_scale = (const float *)b[4].buf, *col_scale = (const float *)b[5].buf;
    const int32_t *roots = (const int32_t *)b[6].buf;
    int32_t *out = (int32_t *)b[7].buf;
    int ok = b[0].len % 32 == 0 && b[3].len / 4 == n && b[4].len / 4 == n &&
             b[5].len / 4 == n && b[7].len / 4 == n * n_trees && levels >= 0 && height >= 0 &&
             width >= 0 && (height + 2) * (width + 2) <= b[1].len / 4;
    for (Py_ssize_t t = 0; t < n_trees && ok; t++)
        if (roots[t] < 0 || roots[t] >= n_nodes) ok = 0;
    if (!ok) {
        for (int i = 0; i < 8; i++) PyBuffer_Release(&b[i]);
        PyErr_SetString(PyExc_ValueError, "descend: inconsistent buffers or roots");
        return NULL;
    }
    const float top_row = (float)(height + 1), top_col = (float)(width + 1);
    const int32_t stride = (int32_t)(width + 2);
    const Py_ssize_t total = n * n_trees, ahead = 16;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t t = 0; t < n_trees; t++)
        for (Py_ssize_t i = 0; i < n; i++) out[t * n + i] = roots[t];
    for (Py_ssize_t level = 0; level < levels && !bad; level++) {
        for (Py_ssize_t j = 0, i = 0; j < total; j++, i = (i + 1 == n) ? 0 : i + 1) {
#if defined(__GNUC__)
            if (j + ahead < total) __builtin_prefetch(table + 8 * (Py_ssize_t)out[j + ahead]);
#endif
            const int32_t *rec = table + 8 * (Py_ssize_t)out[j];
            const float *val = (const float *)rec;
            float r, c;
            r = val[0] * row_scale[i];
            r = r + rows[i];
            r = r < 0.0f ? 0.0f : (r > top_row ? top_row : r);
            c = val[1] * col_scale[i];
            c = c + cols[i];
            c = c < 0.0f ? 0.0f : (c > top_col ? top_col : c);
            const float first = image[(int32_t)r * stride + (int32_t)c];
            r = val[2] * row_scale[i];
            r = r + rows[i];
            r = r < 0.0f ? 0.0f : (r > top_row ? top_row : r);
            c = val[3] * col_scale[i];
            c = c + cols[i];
            c = c < 0.0f ? 0.0f : (c > top_col ? top_col : c);
            const float second = image[(int32_t)r * stride + (int32_t)c];
            const float feature = first - second;
            const int32_t next = feature <= val[4] ? rec[5] : rec[6];
            if (next < 0 || next >= n_nodes) bad = 1; /* never for a validated forest */
            out[j] = bad ? 0 : next;
        }
    }
    Py_END_ALLOW_THREADS
    for (int i = 0; i < 8; i++) PyBuffer_Release(&b[i]);
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "descend: a child index is out of range");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyObject *features(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *objs[7];
    Py_ssize_t height, width;
    if (!PyArg_ParseTuple(args, "OOOOOOnnO", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &height, &width, &objs[6]))
        return NULL;
    Py_buffer b[7];
    int got = 0;
    for (; got < 7; got++) {
        int flags = PyBUF_C_CONTIGUOUS | (got == 6 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(objs[got], &b[got], flags) < 0) break;
        if (b[got].itemsize != 4) {
            PyBuffer_Release(&b[got]);
            PyErr_SetString(PyExc_ValueError, "features: every buffer must hold 32-bit items");
            break;
        }
    }
    if (got < 7) {
        for (int i = 0; i < got; i++) PyBuffer_Release(&b[i]);
        return NULL;
    }
    const Py_ssize_t k = b[0].len / 16;
    const Py_ssize_t n = b[2].len / 4;
    const float *offsets = (const float *)b[0].buf;
    const float *image = (const float *)b[1].buf;
    const float *rows = (const float *)b[2].buf, *cols = (const float *)b[3].buf;
    const float *row_scale = (const float *)b[4].buf, *col_scale = (const float *)b[5].buf;
    float *out = (float *)b[6].buf;
    int ok = b[0].len % 16 == 0 && b[3].len / 4 == n && b[4].len / 4 == n &&
             b[5].len / 4 == n && b[6].len / 4 == n * k && height >= 0 && width >= 0 &&
             (height + 2) * (width + 2) <= b[1].len / 4;
    if (!ok) {
        for (int i = 0; i < 7; i++) PyBuffer_Release(&b[i]);
        PyErr_SetString(PyExc_ValueError, "features: inconsistent buffers");
        return NULL;
    }
    const float top_row = (float)(height + 1), top_col = (float)(width + 1);
    const int32_t stride = (int32_t)(width + 2);
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        const float r0 = rows[i], c0 = cols[i], rs = row_scale[i], cs = col_scale[i];
        float *row_out = out + i * k;
        for (Py_ssize_t j = 0; j < k; j++) {
            const float *val = offsets + 4 * j;
            float r, c;
            r = val[0] * rs;
            r = r + r0;
            r = r < 0.0f ? 0.0f : (r > top_row ? top_row : r);
            c = val[1] * cs;
            c = c + c0;
            c = c < 0.0f ? 0.0f : (c > top_col ? top_col : c);
            const float first = image[(int32_t)r * stride + (int32_t)c];
            r = val[2] * rs;
            r = r + r0;
            r = r < 0.0f ? 0.0f : (r > top_row ? top_row : r);
            c = val[3] * cs;
            c = c + c0;
            c = c < 0.0f ? 0.0f : (c > top_col ? top_col : c);
            row_out[j] = first - image[(int32_t)r * stride + (int32_t)c];
        }
    }
    Py_END_ALLOW_THREADS
    for (int i = 0; i < 7; i++) PyBuffer_Release(&b[i]);
    Py_RETURN_NONE;
}

static PyObject *cast(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *objs[9];
    if (!PyArg_ParseTuple(args, "OOOOOOOOO", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6], &objs[7], &objs[8]))
        return NULL;
    static const Py_ssize_t itemsize[9] = {8, 4, 1, 4, 4, 1, 8, 8, 8};
    Py_buffer b[9];
    int got = 0;
    for (; got < 9; got++) {
        int flags = PyBUF_C_CONTIGUOUS | PyBUF_ND | (got >= 6 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(objs[got], &b[got], flags) < 0) break;
        if (b[got].itemsize != itemsize[got]) {
            PyBuffer_Release(&b[got]);
            PyErr_SetString(PyExc_ValueError, "cast: a buffer has the wrong item size");
            break;
        }
    }
    if (got < 9) {
        for (int i = 0; i < got; i++) PyBuffer_Release(&b[i]);
        return NULL;
    }
    const Py_ssize_t n = b[0].len / 24, n_wanted = b[5].len;
    const Py_ssize_t n_trees = (b[1].ndim == 2) ? b[1].shape[0] : 0;
    const Py_ssize_t per_leaf = (b[2].ndim == 2) ? b[2].shape[1] : 0;
    const Py_ssize_t n_leaves = (b[2].ndim == 2) ? b[2].shape[0] : 0;
    const Py_ssize_t capacity = n_trees * n * per_leaf;
    int ok = b[1].ndim == 2 && b[1].shape[1] == n && b[2].ndim == 2 &&
             b[3].len == 12 * n_leaves * per_leaf && b[4].len == 4 * n_leaves * per_leaf &&
             b[6].len >= 24 * capacity && b[7].len >= 8 * capacity && b[8].len >= 8 * capacity;
    if (!ok) {
        for (int i = 0; i < 9; i++) PyBuffer_Release(&b[i]);
        PyErr_SetString(PyExc_ValueError, "cast: inconsistent buffers");
        return NULL;
    }
    const double *points = (const double *)b[0].buf;
    const int32_t *leaves = (const int32_t *)b[1].buf;
    const int8_t *joint = (const int8_t *)b[2].buf;
    const float *offset = (const float *)b[3].buf, *weight = (const float *)b[4].buf;
    const uint8_t *wanted = (const uint8_t *)b[5].buf;
    double *where = (double *)b[6].buf, *share = (double *)b[8].buf;
    int64_t *joint_out = (int64_t *)b[7].buf;
    const float trees = (float)(n_trees > 0 ? n_trees : 1);
    Py_ssize_t m = 0;
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t j = 0; j < n_trees * n && !bad; j++) {
        const int32_t leaf = leaves[j];
        if (leaf < 0) continue;
        if (leaf >= n_leaves) {
            bad = 1;
            break;
        }
        const double *p = points + 3 * (j % n);
        for (Py_ssize_t k = 0; k < per_leaf; k++) {
            const Py_ssize_t slot = (Py_ssize_t)leaf * per_leaf + k;
            const int8_t which = joint[slot];
            if (!(weight[slot] > 0.0f) || which < 0 || which >= n_wanted || !wanted[which])
                continue;
            const float *o = offset + 3 * slot;
            where[3 * m] = p[0] + (double)o[0];
            where[3 * m + 1] = p[1] + (double)o[1];
            where[3 * m + 2] = p[2] + (double)o[2];
            joint_out[m] = which;
            share[m] = (double)(weight[slot] / trees);
            m++;
        }
    }
    Py_END_ALLOW_THREADS
    for (int i = 0; i < 9; i++) PyBuffer_Release(&b[i]);
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "cast: a leaf row is out of range");
        return NULL;
    }
    return PyLong_FromSsize_t(m);
}

/* Insert candidate (d2, j) into the list (d, id) of `*have` <= k entries, ascending by
 * (d2, j); a full list drops its last entry. */
static inline void knn_insert(double *d, int64_t *id, Py_ssize_t k, Py_ssize_t *have,
                              double d2, int64_t j) {
    Py_ssize_t pos;
    if (*have < k) {
        pos = (*have)++;
    } else {
        if (d2 > d[k - 1] || (d2 == d[k - 1] && j > id[k - 1])) return;
        pos = k - 1;
    }
    while (pos > 0 && (d[pos - 1] > d2 || (d[pos - 1] == d2 && id[pos - 1] > j))) {
        d[pos] = d[pos - 1];
        id[pos] = id[pos - 1];
        --pos;
    }
    d[pos] = d2;
    id[pos] = j;
}

/* One query of knn: the cells at Chebyshev distance r around (cx, cy, cz), clipped. */
static inline void knn_ring(const double *ps, const int64_t *orig, const int32_t *start,
                            const Py_ssize_t dims[3], Py_ssize_t cx, Py_ssize_t cy,
                            Py_ssize_t cz, Py_ssize_t r, double xi, double yi, double zi,
                            double *d, int64_t *id, Py_ssize_t k, Py_ssize_t *have) {
    for (Py_ssize_t z = cz - r; z <= cz + r; z++) {
        if (z < 0 || z >= dims[2]) continue;
        for (Py_ssize_t y = cy - r; y <= cy + r; y++) {
            if (y < 0 || y >= dims[1]) continue;
            /* inside the shell's faces only its two x ends are at distance r */
            const int face = (z == cz - r || z == cz + r || y == cy - r || y == cy + r);
            const Py_ssize_t step = face || r == 0 ? 1 : 2 * r;
            for (Py_ssize_t x = cx - r; x <= cx + r; x += step) {
                if (x < 0 || x >= dims[0]) continue;
                const Py_ssize_t cell = (z * dims[1] + y) * dims[0] + x;
                for (int32_t q = start[cell]; q < start[cell + 1]; q++) {
                    const double dx = xi - ps[3 * q], dy = yi - ps[3 * q + 1];
                    const double dz = zi - ps[3 * q + 2];
                    const double d2 = dx * dx + dy * dy + dz * dz;
                    if (*have < k || d2 <= d[k - 1]) knn_insert(d, id, k, have, d2, orig[q]);
                }
            }
        }
    }
}

static PyObject *knn(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *o_points, *o_dist, *o_idx;
    Py_ssize_t n, k;
    if (!PyArg_ParseTuple(args, "OnnOO", &o_points, &n, &k, &o_dist, &o_idx)) return NULL;
    if (n < 0 || n >= INT32_MAX / 8 || k < 1) {
        PyErr_SetString(PyExc_ValueError, "knn: need 0 <= n < 2^28 and k >= 1");
        return NULL;
    }
    Py_buffer b_points, b_dist, b_idx;
    if (get_buffer(o_points, &b_points, 0, 8, 3 * n, "points") < 0) return NULL;
    if (get_buffer(o_dist, &b_dist, 1, 8, n * k, "dist") < 0) {
        PyBuffer_Release(&b_points);
        return NULL;
    }
    if (get_buffer(o_idx, &b_idx, 1, 8, n * k, "idx") < 0) {
        PyBuffer_Release(&b_points);
        PyBuffer_Release(&b_dist);
        return NULL;
    }
    const double *p = (const double *)b_points.buf;
    double *dist = (double *)b_dist.buf;
    int64_t *idx = (int64_t *)b_idx.buf;
    int ok = 1;
    double lo[3] = {0.0, 0.0, 0.0}, ext[3] = {0.0, 0.0, 0.0}, scale = 0.0;
    for (Py_ssize_t i = 0; i < n && ok; i++)
        for (int a = 0; a < 3; a++)
            if (!isfinite(p[3 * i + a])) ok = 0;
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "knn: non-finite point");
        goto release;
    }
    for (int a = 0; a < 3 && n > 0; a++) {
        double mn = p[a], mx = p[a];
        for (Py_ssize_t i = 1; i < n; i++) {
            const double v = p[3 * i + a];
            mn = v < mn ? v : mn;
            mx = v > mx ? v : mx;
        }
        lo[a] = mn;
        ext[a] = mx - mn;
        scale = fmax(scale, fmax(fabs(mn), fabs(mx)));
    }
    /* Cell size: 1.25 times the median k-th neighbour distance of 16 points spread over
     * the index range (brute force), so that the 27 cells around a point usually hold its
     * k nearest; at most about 8 n cells. Only the time depends on it, not the result. */
    double sample_r[16];
    Py_ssize_t n_sample = n < 16 ? n : 16;
    {
        double *sd = (double *)malloc(sizeof(double) * (size_t)k);
        int64_t *sid = (int64_t *)malloc(sizeof(int64_t) * (size_t)k);
        if (sd == NULL || sid == NULL) {
            free(sd);
            free(sid);
            ok = 0;
            PyErr_NoMemory();
            goto release;
        }
        for (Py_ssize_t s_ = 0; s_ < n_sample; s_++) {
            const Py_ssize_t i = s_ * n / n_sample;
            Py_ssize_t have = 0;
            for (Py_ssize_t j = 0; j < n; j++) {
                const double dx = p[3 * i] - p[3 * j], dy = p[3 * i + 1] - p[3 * j + 1];
                const double dz = p[3 * i + 2] - p[3 * j + 2];
                const double d2 = dx * dx + dy * dy + dz * dz;
                if (have < k || d2 <= sd[k - 1]) knn_insert(sd, sid, k, &have, d2, j);
            }
            sample_r[s_] = sqrt(sd[have - 1]);
        }
        free(sd);
        free(sid);
    }
    for (Py_ssize_t a_ = 1; a_ < n_sample; a_++) /* insertion sort for the median */
        for (Py_ssize_t q = a_; q > 0 && sample_r[q - 1] > sample_r[q]; q--) {
            const double t = sample_r[q];
            sample_r[q] = sample_r[q - 1];
            sample_r[q - 1] = t;
        }
    const double e_max = fmax(ext[0], fmax(ext[1], ext[2]));
    double h = n_sample > 0 ? 1.25 * sample_r[n_sample / 2] : 1.0;
    if (!(h > 1e-9 * e_max)) h = e_max > 0.0 ? e_max / (double)n : 1.0; /* duplicates */
    Py_ssize_t dims[3];
    for (;;) { /* in doubles: a far outlier must not overflow the cell counts */
        double cells = 1.0;
        for (int a = 0; a < 3; a++) cells *= floor(ext[a] / h) + 1.0;
        if (cells <= 8.0 * (double)n + 64.0) break;
        h *= 1.5;
    }
    for (int a = 0; a < 3; a++) dims[a] = (Py_ssize_t)(ext[a] / h) + 1;
    const Py_ssize_t n_cells = dims[0] * dims[1] * dims[2];
    int32_t *start = (int32_t *)calloc((size_t)(n_cells + 1), sizeof(int32_t));
    int32_t *cell_of = (int32_t *)malloc(sizeof(int32_t) * (size_t)(n + 1));
    double *ps = (double *)malloc(sizeof(double) * (size_t)(3 * n + 1));
    int64_t *orig = (int64_t *)malloc(sizeof(int64_t) * (size_t)(n + 1));
    if (start == NULL || cell_of == NULL || ps == NULL || orig == NULL) {
        ok = 0;
        PyErr_NoMemory();
    } else {
        Py_BEGIN_ALLOW_THREADS
        /* Counting sort of the points by cell (ascending index within a cell). */
        for (Py_ssize_t i = 0; i < n; i++) {
            Py_ssize_t c[3];
            for (int a = 0; a < 3; a++) {
                c[a] = (Py_ssize_t)((p[3 * i + a] - lo[a]) / h);
                c[a] = c[a] < 0 ? 0 : (c[a] >= dims[a] ? dims[a] - 1 : c[a]);
            }
            cell_of[i] = (int32_t)((c[2] * dims[1] + c[1]) * dims[0] + c[0]);
            start[cell_of[i] + 1]++;
        }
        for (Py_ssize_t c = 0; c < n_cells; c++) start[c + 1] += start[c];
        for (Py_ssize_t i = 0; i < n; i++) {
            const int32_t q = start[cell_of[i]]++;
            ps[3 * q] = p[3 * i];
            ps[3 * q + 1] = p[3 * i + 1];
            ps[3 * q + 2] = p[3 * i + 2];
            orig[q] = i;
        }
        for (Py_ssize_t c = n_cells; c > 0; c--) start[c] = start[c - 1];
        start[0] = 0;
        const Py_ssize_t max_r = dims[0] > dims[1] ? (dims[0] > dims[2] ? dims[0] : dims[2])
                                                   : (dims[1] > dims[2] ? dims[1] : dims[2]);
        for (Py_ssize_t i = 0; i < n; i++) {
            const double xi = p[3 * i], yi = p[3 * i + 1], zi = p[3 * i + 2];
            const int32_t cell = cell_of[i];
            const Py_ssize_t cx = cell % dims[0], cy = (cell / dims[0]) % dims[1];
            const Py_ssize_t cz = cell / (dims[0] * dims[1]);
            double *d = dist + i * k;
            int64_t *id = idx + i * k;
            Py_ssize_t have = 0;
            for (Py_ssize_t r = 0; r < max_r; r++) {
                knn_ring(ps, orig, start, dims, cx, cy, cz, r, xi, yi, zi, d, id, k, &have);
                /* Points beyond ring r lie at least r h away along some axis, less the
                 * rounding of their cell's index: none of them can enter a list whose
                 * k-th is nearer. */
                const double reach = (double)r * h * (1.0 - 1e-9) - 1e-12 * scale;
                if (have == k && reach > 0.0 && d[k - 1] < reach * reach) break;
            }
            for (Py_ssize_t c = 0; c < have; c++) d[c] = sqrt(d[c]);
            for (Py_ssize_t c = have; c < k; c++) {
                d[c] = INFINITY;
                id[c] = n;
            }
        }
        Py_END_ALLOW_THREADS
    }
    free(start);
    free(cell_of);
    free(ps);
    free(orig);
release:
    PyBuffer_Release(&b_points);
    PyBuffer_Release(&b_dist);
    PyBuffer_Release(&b_idx);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

static PyObject *graph_csr(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *o_points, *o_dist, *o_idx, *o_indptr, *o_indices, *o_data;
    Py_ssize_t n, kk;
    double limit, depth_step;
    if (!PyArg_ParseTuple(args, "OnnOOddOOO", &o_points, &n, &kk, &o_dist, &o_idx, &limit,
                          &depth_step, &o_indptr, &o_indices, &o_data))
        return NULL;
    if (n < 0 || kk < 1 || n * (kk - 1) >= INT32_MAX / 2) {
        PyErr_SetString(PyExc_ValueError, "graph_csr: bad n or kk");
        return NULL;
    }
    const Py_ssize_t half = n * (kk - 1); /* directed edges at most */
    Py_buffer b[6];
    PyObject *objs[6] = {o_points, o_dist, o_idx, o_indptr, o_indices, o_data};
    const Py_ssize_t items[6] = {8, 8, 8, 4, 4, 8};
    const Py_ssize_t counts[6] = {3 * n, n * kk, n * kk, n + 1, 2 * half, 2 * half};
    const char *names[6] = {"points", "dist", "idx", "indptr", "indices", "data"};
    int got = 0;
    for (; got < 6; got++)
        if (get_buffer(objs[got], &b[got], got >= 3, items[got], counts[got], names[got]) < 0)
            break;
    Py_ssize_t nnz = -1;
    int32_t *ends = NULL, *fill = NULL;
    double *lens = NULL;
    if (got == 6) {
        ends = (int32_t *)malloc(sizeof(int32_t) * (size_t)(2 * half + 1));
        fill = (int32_t *)malloc(sizeof(int32_t) * (size_t)(n + 1));
        lens = (double *)malloc(sizeof(double) * (size_t)(half + 1));
        if (ends == NULL || fill == NULL || lens == NULL) PyErr_NoMemory();
    }
    if (got == 6 && ends != NULL && fill != NULL && lens != NULL) {
        const double *p = (const double *)b[0].buf, *dist = (const double *)b[1].buf;
        const int64_t *idx = (const int64_t *)b[2].buf;
        int32_t *indptr = (int32_t *)b[3].buf, *indices = (int32_t *)b[4].buf;
        double *data = (double *)b[5].buf;
        const int cut_steps = !isnan(depth_step);
        /* The kept edges (i, j), in `ends` as pairs, each counted in both of its rows. */
        for (Py_ssize_t v = 0; v <= n; v++) indptr[v] = 0;
        Py_ssize_t m = 0;
        for (Py_ssize_t i = 0; i < n; i++) {
            for (Py_ssize_t c = 1; c < kk; c++) {
                const int64_t j = idx[i * kk + c];
                const double len = dist[i * kk + c];
                if (!(len <= limit) || j < 0 || j >= n || j == i) continue;
                if (cut_steps) {
                    const double dz = fabs(p[3 * j + 2] - p[3 * i + 2]);
                    if (dz > depth_step &&
                        dz > hypot(p[3 * j] - p[3 * i], p[3 * j + 1] - p[3 * i + 1]))
                        continue;
                }
                ends[2 * m] = (int32_t)i;
                ends[2 * m + 1] = (int32_t)j;
                lens[m++] = len < 1e-9 ? 1e-9 : len;
                indptr[i + 1]++;
                indptr[j + 1]++;
            }
        }
        for (Py_ssize_t v = 0; v < n; v++) indptr[v + 1] += indptr[v];
        memcpy(fill, indptr, sizeof(int32_t) * (size_t)(n + 1));
        for (Py_ssize_t e = 0; e < m; e++) { /* both directions, bucketed by row */
            const int32_t i = ends[2 * e], j = ends[2 * e + 1];
            indices[fill[i]] = j;
            data[fill[i]++] = lens[e];
            indices[fill[j]] = i;
            data[fill[j]++] = lens[e];
        }
        /* Each row's columns ascending, an edge found from both ends kept once (its
         * length is the same from each: the squared distance is symmetric). */
        Py_ssize_t out = 0;
        for (Py_ssize_t v = 0; v < n; v++) {
            const Py_ssize_t lo = indptr[v], hi = indptr[v + 1];
            for (Py_ssize_t a = lo + 1; a < hi; a++) {
                const int32_t col = indices[a];
                const double len = data[a];
                Py_ssize_t q = a;
                while (q > lo && indices[q - 1] > col) {
                    indices[q] = indices[q - 1];
                    data[q] = data[q - 1];
                    --q;
                }
                indices[q] = col;
                data[q] = len;
            }
            indptr[v] = (int32_t)out;
            for (Py_ssize_t a = lo; a < hi; a++) {
                if (a > lo && indices[a] == indices[a - 1]) continue;
                indices[out] = indices[a];
                data[out++] = data[a];
            }
        }
        indptr[n] = (int32_t)out;
        nnz = out;
    }
    free(ends);
    free(fill);
    free(lens);
    for (int q = 0; q < got; q++) PyBuffer_Release(&b[q]);
    if (nnz < 0) return NULL;
    return PyLong_FromSsize_t(nnz);
}

static PyObject *part_distances(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *o_points, *o_anchors, *o_labels, *o_reach, *o_indptr, *o_indices, *o_data, *o_out;
    Py_ssize_t n, n_anchors, k;
    if (!PyArg_ParseTuple(args, "OnOnnOOOOOO", &o_points, &n, &o_anchors, &n_anchors, &k,
                          &o_labels, &o_reach, &o_indptr, &o_indices, &o_data, &o_out))
        return NULL;
    if (n < 1 || n > INT32_MAX || k < 1 || n_anchors < 0 || n_anchors % k != 0) {
        PyErr_SetString(PyExc_ValueError, "part_distances: bad n, n_anchors or k");
        return NULL;
    }
    const Py_ssize_t n_parts = n_anchors / k;
    Py_buffer b[8];
    PyObject *objs[8] = {o_points, o_anchors, o_labels, o_reach, o_indptr, o_indices, o_data, o_out};
    const Py_ssize_t items[8] = {8, 8, 8, 8, 4, 4, 8, 8};
    const char *names[8] = {"points", "anchors", "labels", "reach",
                            "indptr", "indices", "data",   "out"};
    int got = 0, ok = 1;
    for (; got < 8 && ok; got++) {
        Py_ssize_t count;
        switch (got) {
        case 0: count = 3 * n; break;
        case 1: count = 3 * n_anchors; break;
        case 2: count = 0; break; /* labels: n or none, checked below */
        case 3: count = 0; break; /* reach: n_parts or none */
        case 4: count = n + 1; break;
        case 5: count = ((const int32_t *)b[4].buf)[n]; break;
        case 6: count = ((const int32_t *)b[4].buf)[n]; break;
        default: count = n_parts * n;
        }
        if (count < 0 ||
            get_buffer(objs[got], &b[got], got == 7, items[got], count, names[got]) < 0) {
            if (count < 0) PyErr_SetString(PyExc_ValueError, "part_distances: bad indptr");
            ok = 0;
            break;
        }
    }
    const int has_labels = ok && b[2].len > 0, has_reach = ok && b[3].len > 0;
    if (ok && ((has_labels && b[2].len != 8 * n) || (has_reach && b[3].len != 8 * n_parts))) {
        PyErr_SetString(PyExc_ValueError, "part_distances: 'labels' or 'reach' has the wrong size");
        ok = 0;
    }
    const int32_t *indptr = ok ? (const int32_t *)b[4].buf : NULL;
    const int32_t *indices = ok ? (const int32_t *)b[5].buf : NULL;
    const Py_ssize_t nnz = ok ? indptr[n] : 0;
    for (Py_ssize_t e = 0; e < nnz && ok; e++)
        if (indices[e] < 0 || indices[e] >= n || !(((const double *)b[6].buf)[e] >= 0.0)) ok = 0;
    for (Py_ssize_t v = 0; v < n && ok; v++)
        if (indptr[v] > indptr[v + 1] || indptr[v] < 0) ok = 0;
    if (!ok && !PyErr_Occurred())
        PyErr_SetString(PyExc_ValueError, "part_distances: invalid graph (indices, lengths)");
    /* work: per anchor its source and gap; the heap and queue of the searches */
    int32_t *source = NULL, *queue = NULL;
    double *gap = NULL;
    unsigned char *has = NULL;
    item *heap = NULL;
    if (ok) {
        source = (int32_t *)malloc(sizeof(int32_t) * (size_t)(n_anchors + 1));
        queue = (int32_t *)malloc(sizeof(int32_t) * (size_t)(n + k + 1));
        gap = (double *)malloc(sizeof(double) * (size_t)(n_anchors + 1));
        has = (unsigned char *)calloc((size_t)(n_parts + 1), 1);
        heap = (item *)malloc(sizeof(item) * (size_t)(nnz + k + 1));
        if (!source || !queue || !gap || !has || !heap) {
            ok = 0;
            PyErr_NoMemory();
        }
    }
    if (ok) {
        const double *p = (const double *)b[0].buf, *anc = (const double *)b[1].buf;
        const int64_t *lab = has_labels ? (const int64_t *)b[2].buf : NULL;
        const double *reach = has_reach ? (const double *)b[3].buf : NULL;
        const double *data = (const double *)b[6].buf;
        double *out = (double *)b[7].buf;
        Py_BEGIN_ALLOW_THREADS
        if (lab)
            for (Py_ssize_t v = 0; v < n; v++)
                if (lab[v] >= 0 && lab[v] < n_parts) has[lab[v]] = 1;
        for (Py_ssize_t j = 0; j < n_parts; j++) {
            /* The part's anchors with their sources, packed to the front of its rows. */
            Py_ssize_t count = 0;
            const int own = lab != NULL && has[j];
            for (Py_ssize_t a = j * k; a < j * k + k; a++) {
                const double ax = anc[3 * a], ay = anc[3 * a + 1], az = anc[3 * a + 2];
                if (!(isfinite(ax) && isfinite(ay) && isfinite(az))) continue;
                /* the first nearest, as np.argmin over the row with the others at +inf
                 * (index 0 where every candidate is infinitely far) */
                double best = INFINITY;
                int32_t arg = 0;
                for (Py_ssize_t v = 0; v < n; v++) {
                    if (own && lab[v] != j) continue;
                    const double dx = ax - p[3 * v], dy = ay - p[3 * v + 1],
                                 dz = az - p[3 * v + 2];
                    const double d2 = dx * dx + dy * dy + dz * dz;
                    if (d2 < best) {
                        best = d2;
                        arg = (int32_t)v;
                    }
                }
                source[j * k + count] = arg;
                gap[j * k + count++] = sqrt(best);
            }
            double *row = out + j * n;
            if (count == 0) {
                for (Py_ssize_t v = 0; v < n; v++) row[v] = INFINITY;
                continue;
            }
            /* exact within the reach, plus 1e-9 and 1e-12 of it (a NaN reach: everywhere) */
            const double r = reach ? reach[j] : INFINITY;
            const double limit = isnan(r) ? INFINITY : (r + 1e-9) + 1e-12 * fabs(r);
            dijkstra_run(indptr, indices, data, n, source + j * k, gap + j * k, count, limit,
                         row, heap, queue);
        }
        Py_END_ALLOW_THREADS
    }
    free(source);
    free(queue);
    free(gap);
    free(has);
    free(heap);
    for (int q = 0; q < got; q++) PyBuffer_Release(&b[q]);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"descend", descend, METH_VARARGS,
     "descend(table, image, rows, cols, row_scale, col_scale, roots, levels, height, width, "
     "out): the forest's descent."},
    {"features", features, METH_VARARGS,
     "features(offsets, image, rows, cols, row_scale, col_scale, height, width, out): every "
     "offset pair's feature at every pixel."},
    {"cast", cast, METH_VARARGS,
     "cast(points, leaves, joint, offset, weight, wanted, where, joint_out, weight_out) -> M: "
     "the joint votes."},
    {"knn", knn, METH_VARARGS,
     "knn(points, n, k, dist, idx): every point's k nearest points (itself included)."},
    {"graph_csr", graph_csr, METH_VARARGS,
     "graph_csr(points, n, kk, dist, idx, limit, depth_step, indptr, indices, data) -> nnz: "
     "the k-NN graph as a symmetric CSR matrix."},
    {"part_distances", part_distances, METH_VARARGS,
     "part_distances(points, n, anchors, n_anchors, k, labels, reach, indptr, indices, data, "
     "out): relabelling's geodesic distance of every point from every part."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_ckernels", "Compiled kernels of posedrift.labelling.", -1, methods,
    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__ckernels(void) { return PyModule_Create(&module); }
