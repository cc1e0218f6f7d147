/* Points to grid cells, their (cell, height) keys, their sort and running sum; a cloud's bounds. */
#include "kernels.h"

/* Per-axis min and max of the first dims (1 to 3) axes of n > 0 points in one pass (numpy twin:
 * soilvolume.core.cells.bounds): point i's axis j at p[i * step + j * axis]; NaN where an axis
 * holds a NaN, as numpy's. */
static inline void extend(double x, double *a, double *b, int *nan, int j) {
    *a = x < *a ? x : *a, *b = x > *b ? x : *b;
    *nan |= (x != x) << j;
}

void sv_bounds(const double *p, int64_t n, int64_t step, int64_t axis, int64_t dims, double *lo, double *hi) {
    double a0 = p[0], b0 = p[0], a1 = 0.0, b1 = 0.0, a2 = 0.0, b2 = 0.0;
    int nan = 0;
    if (dims > 1) a1 = b1 = p[axis];
    if (dims > 2) a2 = b2 = p[2 * axis];
    for (int64_t i = 0; i < n; i++) { /* unrolled per dims: one pass, the axes in registers */
        const double *q = p + i * step;
        extend(q[0], &a0, &b0, &nan, 0);
        if (dims > 1) extend(q[axis], &a1, &b1, &nan, 1);
        if (dims > 2) extend(q[2 * axis], &a2, &b2, &nan, 2);
    }
    const double a[3] = {a0, a1, a2}, b[3] = {b0, b1, b2};
    for (int64_t j = 0; j < dims; j++) lo[j] = nan >> j & 1 ? NAN : a[j], hi[j] = nan >> j & 1 ? NAN : b[j];
}

/* Points to the cells of a grid's window (numpy twins: soilvolume.dem.grid._cells_of on a block,
 * distributed.tiletask._window_cells): float32 x, y, z (step floats apart) to column (x - xmin) *
 * inv and row (ymax - y) * inv in float32, as numpy; those in rows r0..r1, columns c0..c1: their
 * flat id in the window and float64 height appended to ids and z, their offsets in the cell added
 * to sx and sy in order (OffsetSums.add_at). Returns the number appended. */
int64_t sv_cells(const float *x, const float *y, const float *z, int64_t n, int64_t step, float xmin, float ymax,
                 float inv, int64_t r0, int64_t r1, int64_t c0, int64_t c1, int64_t *ids, double *zout, double *sx,
                 double *sy) {
    int64_t m = 0, cols = c1 - c0;
    for (int64_t i = 0; i < n; i++) {
        float col = (x[i * step] - xmin) * inv, row = (ymax - y[i * step]) * inv;
        if (!(col >= (float)c0 && col < (float)c1 && row >= (float)r0 && row < (float)r1)) continue;
        int64_t id = ((int64_t)(int32_t)row - r0) * cols + (int64_t)(int32_t)col - c0;
        ids[m] = id;
        zout[m++] = (double)z[i * step];
        sx[id] += (double)(col - floorf(col));
        sy[id] += (double)(row - floorf(row));
    }
    return m;
}

/* Sort v[0..n) ascending, all of them within lo + 256^passes: least significant digit first, one
 * byte of v - lo a pass, through tmp (n). */
static void radix_i64(int64_t *v, int64_t n, int64_t lo, int passes, int64_t *tmp) {
    int64_t *src = v, *dst = tmp;
    for (int p = 0; p < passes; p++) {
        int64_t at[256] = {0}, total = 0;
        int shift = 8 * p;
        for (int64_t i = 0; i < n; i++) at[((uint64_t)(src[i] - lo) >> shift) & 255]++;
        for (int d = 0; d < 256; d++) {
            int64_t c = at[d];
            at[d] = total, total += c;
        }
        for (int64_t i = 0; i < n; i++) dst[at[((uint64_t)(src[i] - lo) >> shift) & 255]++] = src[i];
        int64_t *t = src;
        src = dst, dst = t;
    }
    if (src != v) memcpy(v, src, (size_t)n * sizeof *v);
}

/* Sort one cell's keys v[0..n): a few by insertion, more by their bytes (radix_i64 through tmp,
 * as many passes as the bytes of their span). */
static void sort_cell(int64_t *v, int64_t n, int64_t *tmp) {
    if (n <= 32) {
        for (int64_t i = 1; i < n; i++) {
            int64_t x = v[i], j = i - 1;
            while (j >= 0 && v[j] > x) v[j + 1] = v[j], j--;
            v[j + 1] = x;
        }
        return;
    }
    int64_t lo = v[0], hi = v[0];
    for (int64_t i = 1; i < n; i++) lo = v[i] < lo ? v[i] : lo, hi = v[i] > hi ? v[i] : hi;
    int passes = 1;
    while (passes < 8 && (uint64_t)(hi - lo) >> (8 * passes)) passes++;
    radix_i64(v, n, lo, passes, tmp);
}

/* Sort int64 keys whose cell is key >> bits (counts: per cell of ncells) into out, next (ncells)
 * for scratch: the keys moved to their cells, then each cell's sorted (the array any sort gives). */
void sv_sort_keys(const int64_t *key, int64_t n, const int64_t *counts, int64_t ncells, int64_t bits, int64_t *out,
                  int64_t *next) {
    int64_t at = 0, most = 0;
    for (int64_t c = 0; c < ncells; c++) next[c] = at, at += counts[c], most = counts[c] > most ? counts[c] : most;
    for (int64_t i = 0; i < n; i++) out[next[key[i] >> bits]++] = key[i];
    int64_t *tmp = most > 32 ? malloc((size_t)most * sizeof *tmp) : NULL;
    at = 0;
    for (int64_t c = 0; c < ncells; c++) {
        sort_cell(out + at, counts[c], tmp);
        at += counts[c];
    }
    free(tmp);
}

/* [0, cumsum(key & top)] in double, one sequential sum (numpy twin: soilvolume.dem.cellstats.
 * _running_sum): out (n + 1). */
void sv_running_sum(const int64_t *key, int64_t n, int64_t top, double *out) {
    double total = 0.0;
    out[0] = total;
    for (int64_t i = 0; i < n; i++) {
        total += (double)(key[i] & top);
        out[i + 1] = total;
    }
}

/* The (cell, height) keys id << bits | (rint(z / q) - base) into key (ids itself may be), the points
 * per cell added to counts (numpy twin: soilvolume.dem.cellstats._SortedCells). */
void sv_keys(const int64_t *ids, const double *z, int64_t n, int64_t base, double q, int64_t bits, int64_t *key,
             int64_t *counts) {
    for (int64_t i = 0; i < n; i++) {
        counts[ids[i]]++; /* before key[i]: it may be ids[i] */
        key[i] = (ids[i] << bits) | ((int64_t)rint(z[i] / q) - base);
    }
}
