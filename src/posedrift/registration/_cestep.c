/* Fused CPD E-step and low-rank M-step (no M x N array), and the low-rank EM loop.
 *
 * estep(target, moved, n, m, d, sigma2, c, eps, single, p1, pt1, px, order[, target_order])
 *     -> (sum_n log(den_n), sum_m P1_m, sum_n Pt1_n |x_n|^2)
 *   target : (N, D) float64 C-contiguous buffer
 *   moved  : (M, D) float64 C-contiguous buffer (the moved source, any order)
 *   eps    : truncation. When eps > 0 and c > 0, only source points within
 *            h = sqrt(-2 sigma2 log(eps c)) of a target point along the source's longest
 *            axis enter its sums: every dropped kernel value is below eps * c, so every
 *            posterior entry is exact to eps absolute.
 *   single : nonzero: kernel values and exponentials in float32 (statistics in float64)
 *   p1     : (M,) float64, written
 *   pt1    : (N,) float64, written
 *   px     : (M, D) float64, written: P X
 *   order  : (M,) int64, read and written: the source permutation sorted along the
 *            truncation axis. Kept by the caller between calls of one registration
 *            (the moved points change little per iteration, so an insertion sort from
 *            the last order is O(M)); anything that is not a permutation is reset.
 *   target_order : optional (N,) int64, the same for the targets: when given, the targets
 *            are visited in increasing order along the axis, so the window slides.
 *
 * lowrank_mstep(zt, m, k, d, p1, px, source, reg, u, moved) -> (ok, sum P.X moved, sum P1 |moved|^2)
 *   The Woodbury M-step in the factor's coordinates (G ~ Z Z', zt = Z' (K, M) C-contiguous,
 *   K a multiple of 4: pad Z with zero columns, whose U rows come out 0):
 *   U = (Z' dP1 Z + reg I)^-1 Z' (P X - dP1 Y) (K, D) into u, moved = Y + Z U (M, D).
 *   ok = 0 when the K x K Cholesky fails (the caller falls back to a checked solve).
 *
 * em_lowrank(target, source, zt, n, m, k, d, w, lambda, floor, eps, sigma2, single, tol,
 *            max_iter, accelerate, order, target_order, u, moved)
 *     -> (ok, iterations, converged, sigma2, objective, c)
 *   register_nonrigid's EM loop with a fixed low-rank factor in one call, step for step
 *   as its Python loop (SQUAREM every second M-step, kept only where the objective is no
 *   worse), from U = 0, moved = source and the given sigma2; estep and lowrank_mstep as
 *   above (eps the truncation). u (K, D) and moved (M, D) are written with the final
 *   iterate. Its sums (|U|^2, the steplength's) run in order where the Python loop's are
 *   NumPy's and BLAS's, so the two agree to rounding. ok = 0 when an M-step's Cholesky
 *   fails: the caller then runs its own loop, which solves that step with checks.
 *
 * label_mass(target, moved, n, m, d, sigma2, c, labels, n_labels, out[, axis, h])
 *   The posterior mass of each label's source points per target point (the tracker's
 *   label transfer): out[n, l] = sum of k_mn over source points m of label l, divided by
 *   den_n = sum_m k_mn + c. labels (M,) int64 in [0, n_labels); out (N, n_labels) float64.
 *   With h > 0 (truncation_halfwidth's distance) each label's points are sorted along
 *   `axis` and a target point sums only those within h of it along the axis: the terms
 *   left out are each below eps c, so every entry moves by less than eps.
 *
 * gauss(a, b, i, j, d, scale, out)
 *   The Gaussian kernel matrix out[i, j] = exp(scale |a_i - b_j|^2) (scale = -1 / (2
 *   beta^2) < 0), a (I, D) and b (J, D) float64, out (I, J) float64; squared differences
 *   summed over the coordinates, exponents clamped at -700 (CPD's Nystrom factor).
 *
 * The NumPy twins are posedrift.registration._estep.estep_numpy,
 * posedrift.registration._estep.posterior_label_mass (compiled=False) and
 * posedrift.registration._cpd._solve_low_rank (and gaussian_kernel's NumPy path); tests
 * compare them. Plain buffer protocol (no NumPy C API). The float64 exponential is a
 * vectorizable Cody-Waite reduction to |r| <= ln(2)/4 (a half-integer power of two) with
 * a degree-10 Taylor polynomial (relative error ~1e-16 on the clamped range [-700, 0]);
 * the float32 one reduces to |r| <= ln(2)/2 with degree 7 (~1e-8 relative, below
 * float32's rounding).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static inline double fast_exp(double x) {
    /* x in [-700, 0]: exp(x) = 2^(k/2) exp(r), |r| <= ln(2)/4, k in [-2020, 0] */
    const double two_log2e = 2.8853900817779268;
    const double half_ln2_hi = 3.46573590184561908245e-01;
    const double half_ln2_lo = 9.5410746463529385001e-11;
    const double shifter = 6755399441055744.0; /* 1.5 * 2^52: low mantissa bits hold k */
    double kd = x * two_log2e + shifter;
    uint64_t ki;
    memcpy(&ki, &kd, sizeof ki);
    kd -= shifter;
    double r = x - kd * half_ln2_hi - kd * half_ln2_lo;
    double p = 1.0 / 3628800.0;
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
    /* kb = k + 2046 in [26, 2046]: 2^(k/2) = 2^(floor(kb/2) - 1023) * (kb odd ? sqrt 2 : 1) */
    const uint64_t kb = (ki + 2046u) & 0xfffu;
    const uint64_t bits = (kb >> 1) << 52;
    double scale;
    memcpy(&scale, &bits, sizeof scale);
    const double odd = (kb & 1u) ? 1.4142135623730951 : 1.0;
    return p * scale * odd;
}

static inline float fast_expf(float x) {
    /* x in [-87, 0] */
    const float log2e = 1.44269504f;
    const float ln2_hi = 0.693359375f;
    const float ln2_lo = -2.12194440e-4f;
    const float shifter = 12582912.0f; /* 1.5 * 2^23 */
    float kf = x * log2e + shifter;
    uint32_t ki;
    memcpy(&ki, &kf, sizeof ki);
    kf -= shifter;
    float r = x - kf * ln2_hi - kf * ln2_lo;
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    uint32_t bits = (ki + 127u) << 23;
    float scale;
    memcpy(&scale, &bits, sizeof scale);
    return p * scale;
}

/* Kernels cloned for the processor found at run time. The AVX2 clone has no FMA: with it
 * the kernels were 15-20% faster on AVX2-only processors, but their rounding moved a
 * degenerate registration (a body onto one point) by 1 nm between units, beyond
 * test_one_sided_single_points_do_not_depend_on_units's nanometre. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define MULTIVERSION __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define MULTIVERSION
#endif

/* Window [lo, hi) of sorted source points with |t_axis - xa| <= h. */
static inline void window(const void *axv, int single, Py_ssize_t m, double xa, double h,
                          Py_ssize_t *lo, Py_ssize_t *hi) {
    const double vlo = xa - h, vhi = xa + h;
    Py_ssize_t l = 0, r = m;
    while (l < r) {
        Py_ssize_t mid = (l + r) / 2;
        double v = single ? (double)((const float *)axv)[mid] : ((const double *)axv)[mid];
        if (v < vlo) l = mid + 1; else r = mid;
    }
    *lo = l;
    r = m;
    while (l < r) {
        Py_ssize_t mid = (l + r) / 2;
        double v = single ? (double)((const float *)axv)[mid] : ((const double *)axv)[mid];
        if (v <= vhi) l = mid + 1; else r = mid;
    }
    *hi = l;
}

/* The window [lo, hi) of the same rule as window() for targets visited in increasing
 * order along `axis`: both ends only move forward. */
#define SLIDE(T, XA)                                                                  \
    do {                                                                              \
        T *ax = mt + axis * m_all;                                                    \
        const double vlo = (XA) - h, vhi = (XA) + h;                                  \
        while (slo < m_all && (double)ax[slo] < vlo) ++slo;                           \
        if (shi < slo) shi = slo;                                                     \
        while (shi < m_all && (double)ax[shi] <= vhi) ++shi;                          \
        lo = slo;                                                                     \
        hi = shi;                                                                     \
    } while (0)

/* Second pass, shared: posterior row -> P1 and P X (float64 accumulation). */
#define ACCUMULATE()                                                                  \
    do {                                                                              \
        double den = s + c;                                                           \
        if (!(den > tiny)) den = tiny;                                                \
        const double inv = 1.0 / den;                                                 \
        pt1[i] = s * inv;                                                             \
        log_den += log(den);                                                          \
        if (d == 3) {                                                                 \
            const double y0 = xd[0] * inv, y1 = xd[1] * inv, y2 = xd[2] * inv;        \
            double *q0 = pxw, *q1 = pxw + m_all, *q2 = pxw + 2 * m_all;                \
            for (Py_ssize_t j = 0; j < mw_n; ++j) {                                   \
                const double k = (double)row[j];                                      \
                p1w[j] += k * inv;                                                    \
                q0[j] += k * y0;                                                      \
                q1[j] += k * y1;                                                      \
                q2[j] += k * y2;                                                      \
            }                                                                         \
        } else {                                                                      \
            for (Py_ssize_t j = 0; j < mw_n; ++j) p1w[j] += (double)row[j] * inv;     \
            for (Py_ssize_t kk = 0; kk < d; ++kk) {                                   \
                const double yk = xd[kk] * inv;                                       \
                double *qk = pxw + kk * m_all;                                        \
                for (Py_ssize_t j = 0; j < mw_n; ++j) qk[j] += (double)row[j] * yk;   \
            }                                                                         \
        }                                                                             \
    } while (0)

/* row[j] = |x - m_j|^2 over the n columns of mt (D rows, `stride` apart), one dimension at
 * a time: the general-D path of the float64 kernels. */
static inline void squared_distances(const double *xd, const double *mt, Py_ssize_t stride,
                                     Py_ssize_t n, Py_ssize_t d, double *row) {
    for (Py_ssize_t j = 0; j < n; ++j) row[j] = 0.0;
    for (Py_ssize_t kk = 0; kk < d; ++kk) {
        const double xk = xd[kk];
        const double *mk = mt + kk * stride;
        for (Py_ssize_t j = 0; j < n; ++j) {
            double e = xk - mk[j];
            row[j] += e * e;
        }
    }
}

/* x (N, D) float64; mt (D, M) sorted source, transposed; p1 (M), pxt (D, M) zeroed. */
MULTIVERSION
static double kernel_f64(const double *x, const double *mt, Py_ssize_t n, Py_ssize_t m_all,
                         Py_ssize_t d, double sigma2, double c, double *p1, double *pt1,
                         double *pxt, double *row, Py_ssize_t axis, double h,
                         const int64_t *tperm) {
    const double a = -0.5 / sigma2;
    const double tiny = 2.2250738585072014e-308;
    double log_den = 0.0;
    Py_ssize_t slo = 0, shi = 0; /* sliding window over targets sorted along `axis` */
    for (Py_ssize_t ii = 0; ii < n; ++ii) {
        const Py_ssize_t i = tperm ? (Py_ssize_t)tperm[ii] : ii;
        const double *xd = x + i * d;
        Py_ssize_t lo = 0, hi = m_all;
        if (h > 0.0 && tperm) {
            SLIDE(const double, xd[axis]);
        } else if (h > 0.0) {
            window(mt + axis * m_all, 0, m_all, xd[axis], h, &lo, &hi);
        }
        const Py_ssize_t mw_n = hi - lo;
        const double *mw = mt + lo;
        double *p1w = p1 + lo, *pxw = pxt + lo;
        double s = 0.0;
        if (d == 3) {
            const double x0 = xd[0], x1 = xd[1], x2 = xd[2];
            const double *m0 = mw, *m1 = mw + m_all, *m2 = mw + 2 * m_all;
#pragma omp simd reduction(+ : s)
            for (Py_ssize_t j = 0; j < mw_n; ++j) {
                double e0 = x0 - m0[j], e1 = x1 - m1[j], e2 = x2 - m2[j];
                double z = a * (e0 * e0 + e1 * e1 + e2 * e2);
                z = z < -700.0 ? -700.0 : z;
                double k = fast_exp(z);
                row[j] = k;
                s += k;
            }
        } else {
            squared_distances(xd, mw, m_all, mw_n, d, row);
#pragma omp simd reduction(+ : s)
            for (Py_ssize_t j = 0; j < mw_n; ++j) {
                double z = a * row[j];
                z = z < -700.0 ? -700.0 : z;
                double k = fast_exp(z);
                row[j] = k;
                s += k;
            }
        }
        ACCUMULATE();
    }
    return log_den;
}

/* The same in float32: xf (N, D) and mt (D, M) float32; statistics float64. */
MULTIVERSION
static double kernel_f32(const float *xf, const double *x, const float *mt, Py_ssize_t n,
                         Py_ssize_t m_all, Py_ssize_t d, double sigma2, double c, double *p1,
                         double *pt1, double *pxt, float *row, Py_ssize_t axis, double h,
                         const int64_t *tperm) {
    const float a = (float)(-0.5 / sigma2);
    const double tiny = 2.2250738585072014e-308;
    double log_den = 0.0;
    Py_ssize_t slo = 0, shi = 0; /* sliding window over targets sorted along `axis` */
    for (Py_ssize_t ii = 0; ii < n; ++ii) {
        const Py_ssize_t i = tperm ? (Py_ssize_t)tperm[ii] : ii;
        const float *xi = xf + i * d;
        const double *xd = x + i * d;
        Py_ssize_t lo = 0, hi = m_all;
        if (h > 0.0 && tperm) {
            SLIDE(const float, (double)xi[axis]);
        } else if (h > 0.0) {
            window(mt + axis * m_all, 1, m_all, (double)xi[axis], h, &lo, &hi);
        }
        const Py_ssize_t mw_n = hi - lo;
        const float *mw = mt + lo;
        double *p1w = p1 + lo, *pxw = pxt + lo;
        double s = 0.0;
        if (d == 3) {
            const float x0 = xi[0], x1 = xi[1], x2 = xi[2];
            const float *m0 = mw, *m1 = mw + m_all, *m2 = mw + 2 * m_all;
            float sf = 0.0f;
            /* blocks of 256 summed in float32, the blocks in float64 */
            for (Py_ssize_t j0 = 0; j0 < mw_n; j0 += 256) {
                const Py_ssize_t j1 = j0 + 256 < mw_n ? j0 + 256 : mw_n;
                sf = 0.0f;
#pragma omp simd reduction(+ : sf)
                for (Py_ssize_t j = j0; j < j1; ++j) {
                    float e0 = x0 - m0[j], e1 = x1 - m1[j], e2 = x2 - m2[j];
                    float z = a * (e0 * e0 + e1 * e1 + e2 * e2);
                    z = z < -87.0f ? -87.0f : z;
                    float k = fast_expf(z);
                    row[j] = k;
                    sf += k;
                }
                s += (double)sf;
            }
        } else {
            for (Py_ssize_t j = 0; j < mw_n; ++j) row[j] = 0.0f;
            for (Py_ssize_t kk = 0; kk < d; ++kk) {
                const float xk = xi[kk];
                const float *mk = mw + kk * m_all;
                for (Py_ssize_t j = 0; j < mw_n; ++j) {
                    float e = xk - mk[j];
                    row[j] += e * e;
                }
            }
            for (Py_ssize_t j0 = 0; j0 < mw_n; j0 += 256) {
                const Py_ssize_t j1 = j0 + 256 < mw_n ? j0 + 256 : mw_n;
                float sf = 0.0f;
#pragma omp simd reduction(+ : sf)
                for (Py_ssize_t j = j0; j < j1; ++j) {
                    float z = a * row[j];
                    z = z < -87.0f ? -87.0f : z;
                    float k = fast_expf(z);
                    row[j] = k;
                    sf += k;
                }
                s += (double)sf;
            }
        }
        ACCUMULATE();
    }
    return log_den;
}

/* x (N, D); mt (D, M) the source transposed and grouped by label, label l's points in
 * columns [first[l], first[l + 1]); out (N, L). Each label's kernel values are summed
 * by a vectorized reduction over its own columns (with h > 0, over those within h of
 * the target point along `axis`, each label's columns sorted along it). */
MULTIVERSION
static void label_mass_f64(const double *x, const double *mt, Py_ssize_t n, Py_ssize_t m,
                           Py_ssize_t d, double sigma2, double c, const Py_ssize_t *first,
                           Py_ssize_t n_labels, Py_ssize_t axis, double h, double *out,
                           double *row) {
    const double a = -0.5 / sigma2;
    const double tiny = 2.2250738585072014e-308;
    const double *ax = mt + axis * m; /* sorted within each label's range when h > 0 */
    for (Py_ssize_t i = 0; i < n; ++i) {
        const double *xd = x + i * d;
        if (d != 3) squared_distances(xd, mt, m, m, d, row);
        double *o = out + i * n_labels;
        double s = 0.0;
        for (Py_ssize_t l = 0; l < n_labels; ++l) {
            Py_ssize_t j0 = first[l], j1 = first[l + 1];
            if (h > 0.0 && j1 > j0) { /* the label's points within h along the axis */
                Py_ssize_t lo, hi;
                window(ax + j0, 0, j1 - j0, xd[axis], h, &lo, &hi);
                j1 = j0 + hi;
                j0 += lo;
            }
            double sl = 0.0;
            if (d == 3) {
                const double x0 = xd[0], x1 = xd[1], x2 = xd[2];
                const double *m0 = mt, *m1 = mt + m, *m2 = mt + 2 * m;
#pragma omp simd reduction(+ : sl)
                for (Py_ssize_t j = j0; j < j1; ++j) {
                    double e0 = x0 - m0[j], e1 = x1 - m1[j], e2 = x2 - m2[j];
                    double z = a * (e0 * e0 + e1 * e1 + e2 * e2);
                    z = z < -700.0 ? -700.0 : z;
                    sl += fast_exp(z);
                }
            } else {
#pragma omp simd reduction(+ : sl)
                for (Py_ssize_t j = j0; j < j1; ++j) {
                    double z = a * row[j];
                    z = z < -700.0 ? -700.0 : z;
                    sl += fast_exp(z);
                }
            }
            o[l] = sl;
            s += sl;
        }
        double den = s + c;
        if (!(den > tiny)) den = tiny;
        for (Py_ssize_t l = 0; l < n_labels; ++l) o[l] /= den;
    }
}

static int check_buf(Py_buffer *b, Py_ssize_t count, Py_ssize_t item, const char *fn,
                     const char *name) {
    if (b->len != count * item || b->itemsize != item) {
        PyErr_Format(PyExc_ValueError, "_cestep.%s: buffer '%s' must hold %zd %zd-byte values",
                     fn, name, count, item);
        return -1;
    }
    return 0;
}

typedef struct {
    double key;
    int64_t idx;
} keyed;

static int cmp_keyed(const void *pa, const void *pb) {
    const keyed *a = (const keyed *)pa, *b = (const keyed *)pb;
    if (a->key < b->key) return -1;
    if (a->key > b->key) return 1;
    return (a->idx > b->idx) - (a->idx < b->idx);
}

/* Make `order` a permutation of 0..m-1 sorted by (key[order[j] * d], order[j]): an
 * insertion sort from the last order (nearly sorted between EM iterations), a qsort when
 * that takes more than 8 M moves or `order` is not a permutation. 0 on out of memory. */
static int sort_order(int64_t *order, const double *key, Py_ssize_t m, Py_ssize_t d) {
    unsigned char *seen = (unsigned char *)calloc((size_t)m, 1);
    if (!seen) return 0;
    int ok = 1;
    for (Py_ssize_t j = 0; ok && j < m; ++j) {
        int64_t o = order[j];
        if (o < 0 || o >= m || seen[o]) ok = 0; else seen[o] = 1;
    }
    free(seen);
    Py_ssize_t moves = 0;
    if (ok) {
        for (Py_ssize_t j = 1; j < m && moves <= 8 * m; ++j) {
            const int64_t o = order[j];
            const double v = key[o * d];
            Py_ssize_t i = j - 1;
            while (i >= 0 &&
                   (key[order[i] * d] > v || (key[order[i] * d] == v && order[i] > o))) {
                order[i + 1] = order[i];
                --i;
                ++moves;
            }
            order[i + 1] = o;
        }
        if (moves <= 8 * m) return 1;
    }
    keyed *tmp = (keyed *)malloc((size_t)m * sizeof(keyed));
    if (!tmp) return 0;
    for (Py_ssize_t j = 0; j < m; ++j) {
        tmp[j].idx = j;
        tmp[j].key = key[j * d];
    }
    qsort(tmp, (size_t)m, sizeof(keyed), cmp_keyed);
    for (Py_ssize_t j = 0; j < m; ++j) order[j] = tmp[j].idx;
    free(tmp);
    return 1;
}

/* The E-step proper (estep's sums into p1, pt1 and px; returns sum_n log den_n, and
 * sum P1 and sum Pt1 |x|^2 through np_out and xpx_out). work: (M + D M) doubles, then
 * (D M + M + N D) items of the kernel's type (float32 when single, else float64). */
static double estep_core(const double *x, const double *mv, Py_ssize_t n, Py_ssize_t m,
                         Py_ssize_t d, double sigma2, double c, double eps, int single,
                         double *p1, double *pt1, double *px, int64_t *order, int64_t *torder,
                         void *work, double *np_out, double *xpx_out) {
    double *p1s = (double *)work, *pxt = p1s + m;
    char *tail = (char *)(pxt + d * m);
    double log_den, np_ = 0.0, xpx = 0.0;
    memset(p1s, 0, sizeof(double) * (size_t)(m + d * m));
    /* truncation half-width along the longest axis of the moved source */
    double h = 0.0;
    Py_ssize_t axis = 0;
    if (c > 0.0 && eps > 0.0) {
        double bound = log(eps * c);
        if (bound < 0.0) h = sqrt(-2.0 * sigma2 * bound);
    }
    if (h > 0.0) {
        double best = -1.0;
        for (Py_ssize_t k = 0; k < d; ++k) {
            double lo = mv[k], hi = mv[k];
            for (Py_ssize_t j = 1; j < m; ++j) {
                double v = mv[j * d + k];
                lo = v < lo ? v : lo;
                hi = v > hi ? v : hi;
            }
            if (hi - lo > best) { best = hi - lo; axis = k; }
        }
        if (h >= best) h = 0.0;
    }
    /* the permutation applied: `order` when truncating, else the identity */
    const int64_t *perm = NULL, *tperm = NULL;
    if (h > 0.0) {
        if (sort_order(order, mv + axis, m, d)) perm = order;
        else h = 0.0; /* out of memory for the sort: no truncation */
    }
    /* targets in increasing order along `axis` (kept by the caller: the target does not
     * move, so after the first sort this is a check): a sliding window, no search */
    if (h > 0.0 && torder && sort_order(torder, x + axis, n, d)) tperm = torder;
#define PERM(j) (perm ? perm[j] : (int64_t)(j))
    if (single) {
        float *mt = (float *)tail, *row = mt + d * m, *xf = row + m;
        for (Py_ssize_t j = 0; j < m; ++j)
            for (Py_ssize_t k = 0; k < d; ++k) mt[k * m + j] = (float)mv[PERM(j) * d + k];
        for (Py_ssize_t i = 0; i < n * d; ++i) xf[i] = (float)x[i];
        log_den = kernel_f32(xf, x, mt, n, m, d, sigma2, c, p1s, pt1, pxt, row, axis, h, tperm);
    } else {
        double *mt = (double *)tail, *row = mt + d * m;
        for (Py_ssize_t j = 0; j < m; ++j)
            for (Py_ssize_t k = 0; k < d; ++k) mt[k * m + j] = mv[PERM(j) * d + k];
        log_den = kernel_f64(x, mt, n, m, d, sigma2, c, p1s, pt1, pxt, row, axis, h, tperm);
    }
    for (Py_ssize_t j = 0; j < m; ++j) {
        const int64_t o = PERM(j);
        p1[o] = p1s[j];
        np_ += p1s[j];
        for (Py_ssize_t k = 0; k < d; ++k) px[o * d + k] = pxt[k * m + j];
    }
    for (Py_ssize_t i = 0; i < n; ++i) {
        double r2 = 0.0;
        for (Py_ssize_t k = 0; k < d; ++k) r2 += x[i * d + k] * x[i * d + k];
        xpx += pt1[i] * r2;
    }
#undef PERM
    *np_out = np_;
    *xpx_out = xpx;
    return log_den;
}

static size_t estep_work_bytes(Py_ssize_t n, Py_ssize_t m, Py_ssize_t d, int single) {
    const size_t item = single ? sizeof(float) : sizeof(double);
    return (size_t)(m + d * m) * sizeof(double) + (size_t)(d * m + m + n * d) * item;
}

static PyObject *py_estep(PyObject *self, PyObject *args) {
    Py_buffer bx, bm, bp1, bpt1, bpx, bord, btord = {0};
    Py_ssize_t n, m, d;
    double sigma2, c, eps;
    int single;
    if (!PyArg_ParseTuple(args, "y*y*nnndddpw*w*w*w*|w*", &bx, &bm, &n, &m, &d, &sigma2, &c,
                          &eps, &single, &bp1, &bpt1, &bpx, &bord, &btord))
        return NULL;
    PyObject *result = NULL;
    void *work = NULL;
    if (n < 1 || m < 1 || d < 1 || !(sigma2 > 0.0) || !(c >= 0.0)) {
        PyErr_SetString(PyExc_ValueError, "_cestep.estep: need n, m, d >= 1, sigma2 > 0, c >= 0");
        goto done;
    }
    if (check_buf(&bx, n * d, 8, "estep", "target") || check_buf(&bm, m * d, 8, "estep", "moved") ||
        check_buf(&bp1, m, 8, "estep", "p1") || check_buf(&bpt1, n, 8, "estep", "pt1") ||
        check_buf(&bpx, m * d, 8, "estep", "px") || check_buf(&bord, m, 8, "estep", "order") ||
        (btord.buf && check_buf(&btord, n, 8, "estep", "target_order")))
        goto done;
    work = malloc(estep_work_bytes(n, m, d, single));
    if (!work) {
        PyErr_NoMemory();
        goto done;
    }
    double log_den, np_, xpx;
    Py_BEGIN_ALLOW_THREADS
    log_den = estep_core((const double *)bx.buf, (const double *)bm.buf, n, m, d, sigma2, c, eps,
                         single, (double *)bp1.buf, (double *)bpt1.buf, (double *)bpx.buf,
                         (int64_t *)bord.buf, (int64_t *)btord.buf, work, &np_, &xpx);
    Py_END_ALLOW_THREADS
    result = Py_BuildValue("(ddd)", log_den, np_, xpx);
done:
    free(work);
    PyBuffer_Release(&bx);
    PyBuffer_Release(&bm);
    PyBuffer_Release(&bp1);
    PyBuffer_Release(&bpt1);
    PyBuffer_Release(&bpx);
    PyBuffer_Release(&bord);
    if (btord.buf) PyBuffer_Release(&btord);
    return result;
}

/* A (K, K) upper triangle = sum_m w_m z_m z_m' from zt (K, M), K a multiple of 4:
 * 4 x 4 tiles of A, sixteen running sums vectorized over m. */
MULTIVERSION
static void weighted_gram(const double *zt, const double *w, Py_ssize_t m, Py_ssize_t k,
                          double *a) {
    for (Py_ssize_t i0 = 0; i0 < k; i0 += 4) {
        const double *r0 = zt + i0 * m, *r1 = r0 + m, *r2 = r1 + m, *r3 = r2 + m;
        for (Py_ssize_t j0 = i0; j0 < k; j0 += 4) {
            const double *c0 = zt + j0 * m, *c1 = c0 + m, *c2 = c1 + m, *c3 = c2 + m;
            double s00 = 0, s01 = 0, s02 = 0, s03 = 0, s10 = 0, s11 = 0, s12 = 0, s13 = 0;
            double s20 = 0, s21 = 0, s22 = 0, s23 = 0, s30 = 0, s31 = 0, s32 = 0, s33 = 0;
#pragma omp simd reduction(+ : s00, s01, s02, s03, s10, s11, s12, s13, s20, s21, s22, s23, s30, s31, s32, s33)
            for (Py_ssize_t r = 0; r < m; ++r) {
                const double wr = w[r];
                const double a0 = wr * r0[r], a1 = wr * r1[r], a2 = wr * r2[r], a3 = wr * r3[r];
                const double b0 = c0[r], b1 = c1[r], b2 = c2[r], b3 = c3[r];
                s00 += a0 * b0; s01 += a0 * b1; s02 += a0 * b2; s03 += a0 * b3;
                s10 += a1 * b0; s11 += a1 * b1; s12 += a1 * b2; s13 += a1 * b3;
                s20 += a2 * b0; s21 += a2 * b1; s22 += a2 * b2; s23 += a2 * b3;
                s30 += a3 * b0; s31 += a3 * b1; s32 += a3 * b2; s33 += a3 * b3;
            }
            double *t = a + i0 * k + j0;
            t[0] = s00; t[1] = s01; t[2] = s02; t[3] = s03; t += k;
            t[0] = s10; t[1] = s11; t[2] = s12; t[3] = s13; t += k;
            t[0] = s20; t[1] = s21; t[2] = s22; t[3] = s23; t += k;
            t[0] = s30; t[1] = s31; t[2] = s32; t[3] = s33;
        }
    }
}

/* dot(a, b) over n, and y += alpha x over n: vectorized helpers */
MULTIVERSION
static double dot(const double *a, const double *b, Py_ssize_t n) {
    double s = 0.0;
#pragma omp simd reduction(+ : s)
    for (Py_ssize_t i = 0; i < n; ++i) s += a[i] * b[i];
    return s;
}

/* The low-rank M-step proper; a: (K K + D K + 2 D M) zeroed doubles of work. */
MULTIVERSION
static int lowrank_core(const double *zt, const double *p1, const double *px,
                        const double *src, Py_ssize_t m, Py_ssize_t k, Py_ssize_t d, double reg,
                        double *u, double *mv, double *a, double *spx_out, double *sp2_out) {
    int ok = 1;
    double spx = 0.0, sp2 = 0.0;
    double *ut = a + k * k, *bt = ut + d * k, *mt = bt + d * m;
    weighted_gram(zt, p1, m, k, a);
    for (Py_ssize_t i = 0; i < k; ++i) a[i * k + i] += reg;
    /* B' = (P X - dP1 Y)' (D, M); rhs ut (D, K) = B' Z */
    for (Py_ssize_t r = 0; r < m; ++r)
        for (Py_ssize_t c = 0; c < d; ++c) bt[c * m + r] = px[r * d + c] - p1[r] * src[r * d + c];
    for (Py_ssize_t c = 0; c < d; ++c)
        for (Py_ssize_t i = 0; i < k; ++i) ut[c * k + i] = dot(bt + c * m, zt + i * m, m);
    /* Cholesky A = R' R, right-looking, R in the upper triangle (row i: a[i, i:]) */
    for (Py_ssize_t i = 0; i < k; ++i) {
        const double s = a[i * k + i];
        if (!(s > 0.0)) {
            ok = 0;
            break;
        }
        const double rii = sqrt(s), inv = 1.0 / rii;
        double *ai = a + i * k;
        ai[i] = rii;
        for (Py_ssize_t j = i + 1; j < k; ++j) ai[j] *= inv;
        for (Py_ssize_t j = i + 1; j < k; ++j) {
            const double f = ai[j];
            double *aj = a + j * k;
            for (Py_ssize_t q = j; q < k; ++q) aj[q] -= f * ai[q];
        }
    }
    if (ok) {
        for (Py_ssize_t c = 0; c < d; ++c) {
            double *uc = ut + c * k;
            for (Py_ssize_t i = 0; i < k; ++i) { /* R' v = rhs */
                const double v = uc[i] / a[i * k + i];
                uc[i] = v;
                const double *ai = a + i * k;
                for (Py_ssize_t q = i + 1; q < k; ++q) uc[q] -= ai[q] * v;
            }
            for (Py_ssize_t i = k - 1; i >= 0; --i) { /* R u = v */
                const double *ai = a + i * k;
                double t = uc[i];
                for (Py_ssize_t q = i + 1; q < k; ++q) t -= ai[q] * uc[q];
                uc[i] = t / ai[i];
            }
            for (Py_ssize_t i = 0; i < k; ++i) u[i * d + c] = uc[i];
            /* moved' row c = Y' row c + sum_i u[i, c] zt[i] */
            double *mc = mt + c * m;
            for (Py_ssize_t r = 0; r < m; ++r) mc[r] = src[r * d + c];
            for (Py_ssize_t i = 0; i < k; i += 4) { /* k is a multiple of 4 */
                const double f0 = uc[i], f1 = uc[i + 1], f2 = uc[i + 2], f3 = uc[i + 3];
                const double *z0 = zt + i * m, *z1 = z0 + m, *z2 = z1 + m, *z3 = z2 + m;
                for (Py_ssize_t r = 0; r < m; ++r)
                    mc[r] += f0 * z0[r] + f1 * z1[r] + f2 * z2[r] + f3 * z3[r];
            }
        }
        for (Py_ssize_t r = 0; r < m; ++r) {
            double q2 = 0.0;
            for (Py_ssize_t c = 0; c < d; ++c) {
                const double t = mt[c * m + r];
                mv[r * d + c] = t;
                spx += px[r * d + c] * t;
                q2 += t * t;
            }
            sp2 += p1[r] * q2;
        }
    }
    *spx_out = spx;
    *sp2_out = sp2;
    return ok;
}

static PyObject *py_lowrank_mstep(PyObject *self, PyObject *args) {
    Py_buffer bz, bp1, bpx, bsrc, bu, bmv;
    Py_ssize_t m, k, d;
    double reg;
    if (!PyArg_ParseTuple(args, "y*nnny*y*y*dw*w*", &bz, &m, &k, &d, &bp1, &bpx, &bsrc, &reg,
                          &bu, &bmv))
        return NULL;
    PyObject *result = NULL;
    double *a = NULL;
    if (m < 1 || k < 1 || k % 4 != 0 || d < 1 || !(reg > 0.0)) {
        PyErr_SetString(PyExc_ValueError,
                        "_cestep.lowrank_mstep: need m, d >= 1, k >= 4 a multiple of 4, reg > 0");
        goto done;
    }
    if (check_buf(&bz, m * k, 8, "lowrank_mstep", "zt") ||
        check_buf(&bp1, m, 8, "lowrank_mstep", "p1") ||
        check_buf(&bpx, m * d, 8, "lowrank_mstep", "px") ||
        check_buf(&bsrc, m * d, 8, "lowrank_mstep", "source") ||
        check_buf(&bu, k * d, 8, "lowrank_mstep", "u") ||
        check_buf(&bmv, m * d, 8, "lowrank_mstep", "moved"))
        goto done;
    /* work: A (K, K), ut (D, K), bt (D, M), mt (D, M) */
    a = (double *)calloc((size_t)(k * k + d * k + 2 * d * m), sizeof(double));
    if (!a) {
        PyErr_NoMemory();
        goto done;
    }
    const double *zt = (const double *)bz.buf, *p1 = (const double *)bp1.buf;
    const double *px = (const double *)bpx.buf, *src = (const double *)bsrc.buf;
    double *u = (double *)bu.buf, *mv = (double *)bmv.buf;
    int ok = 1;
    double spx = 0.0, sp2 = 0.0;
    Py_BEGIN_ALLOW_THREADS
    ok = lowrank_core(zt, p1, px, src, m, k, d, reg, u, mv, a, &spx, &sp2);
    Py_END_ALLOW_THREADS
    result = Py_BuildValue("(idd)", ok, spx, sp2);
done:
    free(a);
    PyBuffer_Release(&bz);
    PyBuffer_Release(&bp1);
    PyBuffer_Release(&bpx);
    PyBuffer_Release(&bsrc);
    PyBuffer_Release(&bu);
    PyBuffer_Release(&bmv);
    return result;
}

/* Whether v is finite, from its bits (this file is built with -ffinite-math-only). */
static inline int finite_bits(double v) {
    uint64_t u;
    memcpy(&u, &v, sizeof u);
    return ((u >> 52) & 0x7ffu) != 0x7ffu;
}

static inline double relative_change(double new_, double old) {
    const double scale = fabs(new_) > 1e-300 ? fabs(new_) : 1e-300;
    return fabs(new_ - old) / scale;
}

/* One EM iterate: the field's coordinates u (K, D), the moved source (M, D), sigma^2. */
typedef struct {
    double *u, *mv, s2;
} em_state;

/* The E-step's statistics at an iterate, its outlier term and objective. */
typedef struct {
    double *p1, *pt1, *px, log_den, np_, xpx, c, obj;
} em_stats;

typedef struct {
    const double *x, *src, *zt;
    Py_ssize_t n, m, k, d;
    double w, lam, floor, eps;
    int single;
    int64_t *order, *torder;
    void *estep_work;
    double *mstep_work;
} em_problem;

static void em_estep(const em_problem *pb, const em_state *s, em_stats *st) {
    const Py_ssize_t n = pb->n, m = pb->m, d = pb->d;
    /* outlier_constant, operation for operation */
    st->c = pb->w == 0.0 ? 0.0
                         : pow(2.0 * 3.141592653589793 * s->s2, (double)d / 2.0) * pb->w /
                               (1.0 - pb->w) * (double)m / (double)n;
    st->log_den = estep_core(pb->x, s->mv, n, m, d, s->s2, st->c, pb->eps, pb->single, st->p1,
                             st->pt1, st->px, pb->order, pb->torder, pb->estep_work, &st->np_,
                             &st->xpx);
    double reg = 0.0; /* tr(W' G W) = |U|^2 with G ~ Z Z' */
    for (Py_ssize_t i = 0; i < pb->k * d; ++i) reg += s->u[i] * s->u[i];
    st->obj = -st->log_den + 0.5 * (double)n * (double)d * log(s->s2) + 0.5 * pb->lam * reg;
}

static int em_mstep(const em_problem *pb, const em_stats *st, double s2, em_state *out) {
    const Py_ssize_t m = pb->m, k = pb->k, d = pb->d;
    double pxm, tpt;
    memset(pb->mstep_work, 0, sizeof(double) * (size_t)(k * k + d * k + 2 * d * m));
    if (!lowrank_core(pb->zt, st->p1, st->px, pb->src, m, k, d, s2 * pb->lam, out->u, out->mv,
                      pb->mstep_work, &pxm, &tpt))
        return 0;
    const double s2_new = fabs(st->xpx - 2.0 * pxm + tpt) / (st->np_ * (double)d);
    out->s2 = s2_new > pb->floor ? s2_new : pb->floor;
    return 1;
}

/* The accelerated low-rank EM loop of register_nonrigid (its Python loop, step for step:
 * SQUAREM scheme S3 every second M-step, the extrapolation kept only when its objective
 * is no worse). 0 when an M-step's Cholesky fails (the caller then runs its own loop). */
static int em_loop(const em_problem *pb, em_state *states, em_stats *stats, double s2_0,
                   double tol, Py_ssize_t max_iter, int accelerate, Py_ssize_t *it_out,
                   int *converged_out, em_state **final, em_stats **final_stats) {
    const Py_ssize_t m = pb->m, k = pb->k, d = pb->d;
    em_state *cur = &states[0];
    em_stats *st = &stats[0], *spare = &stats[1];
    memset(cur->u, 0, sizeof(double) * (size_t)(k * d));
    memcpy(cur->mv, pb->src, sizeof(double) * (size_t)(m * d));
    cur->s2 = s2_0;
    em_estep(pb, cur, st);
    double objective = st->obj, obj_1;
    double step_max = 4.0;
    Py_ssize_t it = 0;
    int converged = 0;
#define OTHER(a, b, c) \
    (&states[0] != (a) && &states[0] != (b) && &states[0] != (c) ? &states[0] \
     : &states[1] != (a) && &states[1] != (b) && &states[1] != (c) ? &states[1] \
     : &states[2] != (a) && &states[2] != (b) && &states[2] != (c) ? &states[2] \
                                                                   : &states[3])
    for (;;) {
        if (it >= max_iter) break;
        if (st->np_ <= 0.0) { /* every target point is an outlier: nothing to fit */
            converged = 1;
            break;
        }
        em_state *prev = cur, *next = OTHER(prev, prev, prev);
        if (!em_mstep(pb, st, cur->s2, next)) return 0;
        it++;
        em_estep(pb, next, spare);
        const int done = relative_change(spare->obj, objective) <= tol;
        objective = spare->obj;
        cur = next;
        em_stats *t = st; st = spare; spare = t;
        if (done) {
            converged = 1;
            break;
        }
        if (!accelerate || it + 2 > max_iter || st->np_ <= 0.0) continue;
        em_state *th0 = prev, *th1 = cur, *th2 = OTHER(th0, th1, th1);
        if (!em_mstep(pb, st, cur->s2, th2)) return 0;
        it++;
        double rr = 0.0, vv = 0.0;
        for (Py_ssize_t i = 0; i < m * d; ++i) {
            const double r = th1->mv[i] - th0->mv[i];
            const double v = th2->mv[i] - th1->mv[i] - r;
            rr += r * r;
            vv += v * v;
        }
        double alpha = vv > 0.0 ? -sqrt(rr / vv) : -1.0;
        alpha = alpha < -1.0 ? alpha : -1.0;
        alpha = alpha > -step_max ? alpha : -step_max;
        int fallback = 1;
        if (alpha < -1.0) {
            const double l0 = log(th0->s2), l1 = log(th1->s2), l2 = log(th2->s2);
            double ls = l0 - 2.0 * alpha * (l1 - l0) + alpha * alpha * (l2 - 2.0 * l1 + l0);
            double top = l0 > l1 ? l0 : l1;
            top = top > l2 ? top : l2;
            ls = ls < top + 5.0 ? ls : top + 5.0; /* no overflow; such a step is rejected */
            em_state *ext = OTHER(th0, th1, th2);
            for (Py_ssize_t i = 0; i < k * d; ++i)
                ext->u[i] = th0->u[i] - 2.0 * alpha * (th1->u[i] - th0->u[i]) +
                            alpha * alpha * (th2->u[i] - 2.0 * th1->u[i] + th0->u[i]);
            for (Py_ssize_t i = 0; i < m * d; ++i)
                ext->mv[i] = th0->mv[i] - 2.0 * alpha * (th1->mv[i] - th0->mv[i]) +
                             alpha * alpha * (th2->mv[i] - 2.0 * th1->mv[i] + th0->mv[i]);
            const double s2_ext = exp(ls);
            ext->s2 = s2_ext > pb->floor ? s2_ext : pb->floor;
            em_estep(pb, ext, spare);
            if (finite_bits(spare->obj) && spare->obj <= objective) {
                fallback = 0;
                if (alpha <= -step_max) step_max *= 4.0;
                cur = ext;
                t = st; st = spare; spare = t;
                obj_1 = objective;
                objective = st->obj;
            }
        }
        if (fallback) {
            em_estep(pb, th2, spare);
            cur = th2;
            t = st; st = spare; spare = t;
            obj_1 = objective;
            objective = st->obj;
        }
        if (relative_change(objective, obj_1) <= tol) {
            converged = 1;
            break;
        }
    }
#undef OTHER
    *it_out = it;
    *converged_out = converged;
    *final = cur;
    *final_stats = st;
    return 1;
}

static PyObject *py_em_lowrank(PyObject *self, PyObject *args) {
    Py_buffer bx, bsrc, bz, bord, btord, bu, bmv;
    Py_ssize_t n, m, k, d, max_iter;
    double w, lam, floor_, eps, s2_0, tol;
    int single, accelerate;
    if (!PyArg_ParseTuple(args, "y*y*y*nnnndddddpdnpw*w*w*w*", &bx, &bsrc, &bz, &n, &m, &k, &d,
                          &w, &lam, &floor_, &eps, &s2_0, &single, &tol, &max_iter, &accelerate,
                          &bord, &btord, &bu, &bmv))
        return NULL;
    PyObject *result = NULL;
    double *mem = NULL;
    void *ework = NULL;
    if (n < 1 || m < 1 || k < 4 || k % 4 != 0 || d < 1 || !(s2_0 > 0.0) || !(lam > 0.0) ||
        !(w >= 0.0 && w < 1.0) || max_iter < 0) {
        PyErr_SetString(PyExc_ValueError,
                        "_cestep.em_lowrank: need n, m, d >= 1, k >= 4 a multiple of 4, "
                        "sigma2 > 0, lambda > 0, 0 <= w < 1, max_iter >= 0");
        goto done;
    }
    if (check_buf(&bx, n * d, 8, "em_lowrank", "target") ||
        check_buf(&bsrc, m * d, 8, "em_lowrank", "source") ||
        check_buf(&bz, k * m, 8, "em_lowrank", "zt") ||
        check_buf(&bord, m, 8, "em_lowrank", "order") ||
        check_buf(&btord, n, 8, "em_lowrank", "target_order") ||
        check_buf(&bu, k * d, 8, "em_lowrank", "u") ||
        check_buf(&bmv, m * d, 8, "em_lowrank", "moved"))
        goto done;
    /* four iterates, two sets of statistics, the M-step's work */
    const size_t per_state = (size_t)(k * d + m * d), per_stats = (size_t)(m + n + m * d);
    const size_t mwork = (size_t)(k * k + d * k + 2 * d * m);
    mem = (double *)malloc(sizeof(double) * (4 * per_state + 2 * per_stats + mwork));
    ework = malloc(estep_work_bytes(n, m, d, single));
    if (!mem || !ework) {
        PyErr_NoMemory();
        goto done;
    }
    em_state states[4];
    em_stats stats[2];
    for (int i = 0; i < 4; ++i) {
        states[i].u = mem + i * per_state;
        states[i].mv = states[i].u + k * d;
    }
    for (int i = 0; i < 2; ++i) {
        stats[i].p1 = mem + 4 * per_state + i * per_stats;
        stats[i].pt1 = stats[i].p1 + m;
        stats[i].px = stats[i].pt1 + n;
    }
    em_problem pb = {(const double *)bx.buf, (const double *)bsrc.buf, (const double *)bz.buf,
                     n, m, k, d, w, lam, floor_, eps, single, (int64_t *)bord.buf,
                     (int64_t *)btord.buf, ework, mem + 4 * per_state + 2 * per_stats};
    Py_ssize_t it = 0;
    int converged = 0, ok;
    em_state *fin = NULL;
    em_stats *fst = NULL;
    Py_BEGIN_ALLOW_THREADS
    ok = em_loop(&pb, states, stats, s2_0, tol, max_iter, accelerate, &it, &converged, &fin, &fst);
    if (ok) {
        memcpy(bu.buf, fin->u, sizeof(double) * (size_t)(k * d));
        memcpy(bmv.buf, fin->mv, sizeof(double) * (size_t)(m * d));
    }
    Py_END_ALLOW_THREADS
    if (ok)
        result = Py_BuildValue("(iniddd)", 1, it, converged, fin->s2, fst->obj, fst->c);
    else
        result = Py_BuildValue("(iniddd)", 0, it, 0, 0.0, 0.0, 0.0);
done:
    free(mem);
    free(ework);
    PyBuffer_Release(&bx);
    PyBuffer_Release(&bsrc);
    PyBuffer_Release(&bz);
    PyBuffer_Release(&bord);
    PyBuffer_Release(&btord);
    PyBuffer_Release(&bu);
    PyBuffer_Release(&bmv);
    return result;
}

static PyObject *py_label_mass(PyObject *self, PyObject *args) {
    Py_buffer bx, bm, blab, bout;
    Py_ssize_t n, m, d, n_labels, axis = 0;
    double sigma2, c, h = 0.0;
    if (!PyArg_ParseTuple(args, "y*y*nnnddy*nw*|nd", &bx, &bm, &n, &m, &d, &sigma2, &c, &blab,
                          &n_labels, &bout, &axis, &h))
        return NULL;
    PyObject *result = NULL;
    double *work = NULL;
    Py_ssize_t *first = NULL;
    if (n < 1 || m < 1 || d < 1 || n_labels < 1 || !(sigma2 > 0.0) || !(c >= 0.0) ||
        axis < 0 || axis >= d || !(h >= 0.0)) {
        PyErr_SetString(PyExc_ValueError,
                        "_cestep.label_mass: need n, m, d, n_labels >= 1, sigma2 > 0, c >= 0, "
                        "0 <= axis < d, h >= 0");
        goto done;
    }
    if (check_buf(&bx, n * d, 8, "label_mass", "target") ||
        check_buf(&bm, m * d, 8, "label_mass", "moved") ||
        check_buf(&blab, m, 8, "label_mass", "labels") ||
        check_buf(&bout, n * n_labels, 8, "label_mass", "out"))
        goto done;
    const int64_t *lab = (const int64_t *)blab.buf;
    for (Py_ssize_t j = 0; j < m; ++j) {
        if (lab[j] < 0 || lab[j] >= n_labels) {
            PyErr_Format(PyExc_ValueError, "_cestep.label_mass: labels must lie in [0, %zd)",
                         n_labels);
            goto done;
        }
    }
    work = (double *)malloc((size_t)(d * m + m) * sizeof(double));
    first = (Py_ssize_t *)calloc((size_t)(2 * n_labels + 1), sizeof(Py_ssize_t));
    keyed *by_axis = h > 0.0 ? (keyed *)malloc((size_t)m * sizeof(keyed)) : NULL;
    if (!work || !first || (h > 0.0 && !by_axis)) {
        free(by_axis);
        PyErr_NoMemory();
        goto done;
    }
    const double *x = (const double *)bx.buf, *mv = (const double *)bm.buf;
    double *out = (double *)bout.buf;
    Py_BEGIN_ALLOW_THREADS
    /* counting sort of the source by label: label l's points go to [first[l], first[l+1]),
     * in index order, or with a window (h > 0) in order along the axis */
    Py_ssize_t *next = first + n_labels + 1;
    for (Py_ssize_t j = 0; j < m; ++j) ++first[lab[j] + 1];
    for (Py_ssize_t l = 0; l < n_labels; ++l) {
        first[l + 1] += first[l];
        next[l] = first[l];
    }
    if (by_axis) {
        for (Py_ssize_t j = 0; j < m; ++j) {
            by_axis[j].key = mv[j * d + axis];
            by_axis[j].idx = j;
        }
        qsort(by_axis, (size_t)m, sizeof(keyed), cmp_keyed);
    }
    double *mt = work, *row = work + d * m;
    for (Py_ssize_t q = 0; q < m; ++q) {
        const Py_ssize_t j = by_axis ? (Py_ssize_t)by_axis[q].idx : q;
        const Py_ssize_t col = next[lab[j]]++;
        for (Py_ssize_t k = 0; k < d; ++k) mt[k * m + col] = mv[j * d + k];
    }
    label_mass_f64(x, mt, n, m, d, sigma2, c, first, n_labels, axis, h, out, row);
    Py_END_ALLOW_THREADS
    free(by_axis);
    result = Py_None;
    Py_INCREF(result);
done:
    free(work);
    free(first);
    PyBuffer_Release(&bx);
    PyBuffer_Release(&bm);
    PyBuffer_Release(&blab);
    PyBuffer_Release(&bout);
    return result;
}

/* out (I, J) = exp(scale |a_i - b_j|^2); bt (D, J) is b transposed. */
MULTIVERSION
static void gauss_f64(const double *a, const double *bt, Py_ssize_t ni, Py_ssize_t nj,
                      Py_ssize_t d, double scale, double *out) {
    for (Py_ssize_t i = 0; i < ni; ++i) {
        double *row = out + i * nj;
        squared_distances(a + i * d, bt, nj, nj, d, row);
#pragma omp simd
        for (Py_ssize_t j = 0; j < nj; ++j) {
            double z = scale * row[j];
            z = z < -700.0 ? -700.0 : z;
            row[j] = fast_exp(z);
        }
    }
}

static PyObject *py_gauss(PyObject *self, PyObject *args) {
    Py_buffer ba, bb, bout;
    Py_ssize_t ni, nj, d;
    double scale;
    if (!PyArg_ParseTuple(args, "y*y*nnndw*", &ba, &bb, &ni, &nj, &d, &scale, &bout))
        return NULL;
    PyObject *result = NULL;
    double *bt = NULL;
    if (ni < 0 || nj < 0 || d < 1 || !(scale <= 0.0)) {
        PyErr_SetString(PyExc_ValueError, "_cestep.gauss: need i, j >= 0, d >= 1, scale <= 0");
        goto done;
    }
    if (check_buf(&ba, ni * d, 8, "gauss", "a") || check_buf(&bb, nj * d, 8, "gauss", "b") ||
        check_buf(&bout, ni * nj, 8, "gauss", "out"))
        goto done;
    bt = (double *)malloc((size_t)(d * nj + 1) * sizeof(double));
    if (!bt) {
        PyErr_NoMemory();
        goto done;
    }
    const double *a = (const double *)ba.buf, *b = (const double *)bb.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t j = 0; j < nj; ++j)
        for (Py_ssize_t k = 0; k < d; ++k) bt[k * nj + j] = b[j * d + k];
    gauss_f64(a, bt, ni, nj, d, scale, (double *)bout.buf);
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    free(bt);
    PyBuffer_Release(&ba);
    PyBuffer_Release(&bb);
    PyBuffer_Release(&bout);
    return result;
}

static PyMethodDef methods[] = {
    {"estep", py_estep, METH_VARARGS,
     "estep(target, moved, n, m, d, sigma2, c, eps, single, p1, pt1, px, order[, target_order])"
     " -> (sum log den, sum P1, sum Pt1 |x|^2)"},
    {"lowrank_mstep", py_lowrank_mstep, METH_VARARGS,
     "lowrank_mstep(zt, m, k, d, p1, px, source, reg, u, moved)"
     " -> (ok, sum PX . moved, sum P1 |moved|^2)"},
    {"em_lowrank", py_em_lowrank, METH_VARARGS,
     "em_lowrank(target, source, zt, n, m, k, d, w, lambda, floor, eps, sigma2, single, tol, "
     "max_iter, accelerate, order, target_order, u, moved) -> (ok, iterations, converged, "
     "sigma2, objective, c)"},
    {"gauss", py_gauss, METH_VARARGS,
     "gauss(a, b, i, j, d, scale, out) -> None: the Gaussian kernel matrix"},
    {"label_mass", py_label_mass, METH_VARARGS,
     "label_mass(target, moved, n, m, d, sigma2, c, labels, n_labels, out[, axis, h]) -> None"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cestep",
                                    "Fused CPD E-step (float64 or float32), low-rank M-step and label transfer.",
                                    -1, methods};

PyMODINIT_FUNC PyInit__cestep(void) { return PyModule_Create(&module); }
