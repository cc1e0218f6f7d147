/* soilvolume's native kernels: loops numpy runs as many passes over memory, in one pass each.
 * Plain C99 loaded with ctypes (the GIL released for the call). Each kernel does its numpy twin's
 * (named in its comment) double operations in the same order, built with -ffp-contract=off: a run
 * gives the same bits with or without it (tests/test_native.py). */

#define _POSIX_C_SOURCE 200809L /* pread */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifndef _WIN32
#include <errno.h>
#include <sys/types.h>
#include <unistd.h>
#endif

/* The layout version of the structures below; the loader refuses a library of another. */
int64_t sv_abi(void) { return 1; }

/* One chunk of a LAS/LAZ file streamed into the working frame (numpy twin:
 * soilvolume.inputs.chunkwork.numpy_chunk). */
typedef struct {
    /* the point records: X, Y, Z are int32 at field[k] bytes into each record of stride bytes */
    const uint8_t *rec;
    int64_t n, stride;
    int64_t field[3];
    double scale[3], offset[3], origin[3];
    /* per point label (0: soil), or NULL: every point is soil */
    const uint8_t *labels;
    /* the crop: a polygon rasterized on a lattice (origin plo, cell pres, prows x pcols cells)
     * framed by a border of zeros ((prows + 2) x (pcols + 2) bytes); NULL: no crop */
    const uint8_t *framed;
    double plo[2], pres;
    int64_t prows, pcols;
    /* the thinning lattice (inputs.thinning.ColumnThinner): column sums x, y, z, count (4 x ncols).
     * numpy adds each chunk's sums (from zero in point order) to them; here a point is added onto
     * its column's sums, those of earlier chunks set aside first (side_ids, side: 4 doubles each)
     * and added back when the chunk ends (flush): b + a, the same bits, no chunk-sized sums to
     * fault in. mark (int32, ncols, zeros): the chunk (from 1) that last touched each column. */
    double tlo[2], voxel;
    int64_t first[2], shape[2], ncols;
    double *sums;
    int32_t *mark;
    int64_t *side_ids;
    double *side;
    int64_t nside, chunk, flush;
    /* the points kept at full resolution: those within box (lo x, lo y, hi x, hi y) when use_box */
    int64_t use_box;
    double box[4];
    float *out;            /* soil points kept, (n, 3) room */
    float *others;         /* points that are not soil, within the crop and the box, (n, 3) room */
    uint8_t *other_labels; /* their labels, n room */
    /* results */
    int64_t cropped, kept, other, soil;
    double lo[3], hi[3]; /* per axis min and max of X * scale + offset (absolute) */
} sv_chunk_t;

static inline int32_t load_i32(const uint8_t *p) {
    int32_t v;
    memcpy(&v, p, 4);
    return v;
}

/* The polygon lattice's index of a coordinate: int((v - lo) / res) clipped to -1..top
 * (PolygonMask._cell). */
static inline int64_t lattice(double v, double lo, double res, int64_t top) {
    double t = (v - lo) / res;
    if (!(t >= -1.0)) return -1; /* NaN too */
    if (t > (double)top) return top;
    return (int64_t)t;
}

/* A thinning column along one axis: int((v - lo) / voxel) - first (ColumnThinner._index), or -1
 * where numpy's conversion would overflow (the caller's unsigned bound test fails both). */
static inline int64_t column(double v, double lo, double voxel, int64_t first) {
    double t = (v - lo) / voxel;
    if (!(t > -9.2e18 && t < 9.2e18)) return -1;
    return (int64_t)t - first;
}

static inline void put3f(float *o, const double *p) { o[0] = (float)p[0], o[1] = (float)p[1], o[2] = (float)p[2]; }

static inline int in_box(const double *p, const double *box) {
    return p[0] >= box[0] && p[0] <= box[2] && p[1] >= box[1] && p[1] <= box[3];
}

/* Add a point to its column: straight onto the sums, once the column's earlier sums are set aside.
 * A column no chunk touched yet (mark 0) still has zero sums: they are written, 0.0 + the point's,
 * not read first. A read of a page never written maps the shared zero page, and the write after it
 * faults again and flushes the TLB of every core running the process (the paper pair: ~50 ms). */
static inline void thin_add(sv_chunk_t *c, int64_t id, const double *p) {
    int64_t n = c->ncols;
    double *s = c->sums;
    const double v[4] = {p[0], p[1], p[2], 1.0};
    if (c->mark[id] != (int32_t)c->chunk) {
        int fresh = c->mark[id] == 0;
        c->mark[id] = (int32_t)c->chunk;
        if (fresh) { /* 0.0 + v: the bits of the zero sums plus v (-0.0 too) */
            for (int a = 0; a < 4; a++) s[a * n + id] = 0.0 + v[a];
            return;
        }
        double *keep = c->side + 4 * c->nside;
        c->side_ids[c->nside++] = id;
        for (int a = 0; a < 4; a++) keep[a] = s[a * n + id], s[a * n + id] = 0.0;
    }
    for (int a = 0; a < 4; a++) s[a * n + id] += v[a];
}

/* The end of a chunk: the sums set aside added back (numpy: earlier sums + this chunk's). */
static void thin_flush(sv_chunk_t *c) {
    int64_t n = c->ncols;
    for (int64_t k = 0; k < c->nside; k++)
        for (int a = 0; a < 4; a++) {
            double *sum = c->sums + a * n + c->side_ids[k];
            *sum = c->side[4 * k + a] + *sum;
        }
    c->nside = 0;
    c->chunk++;
}

/* The points of n records at rec through the chunk's work; a point's label is labels[i], else
 * table[rec[cls_at] & cls_mask] (a LAS classification's), else soil. Counts and bounds add up in c. */
static void chunk_points(sv_chunk_t *c, const uint8_t *rec, int64_t n, const uint8_t *labels, const uint8_t *table,
                         int64_t cls_at, int64_t cls_mask) {
    int64_t cropped = 0, kept = c->kept, other = c->other, soil = 0;
    double *mn = c->lo, *mx = c->hi;
    for (int64_t i = 0; i < n; i++) {
        const uint8_t *r = rec + i * c->stride;
        double p[3];
        for (int k = 0; k < 3; k++) { /* decoded_xyz: X * scale + offset, minus origin */
            double t = (double)load_i32(r + c->field[k]) * c->scale[k];
            t = t + c->offset[k];
            if (t < mn[k]) mn[k] = t;
            if (t > mx[k]) mx[k] = t;
            p[k] = t - c->origin[k];
        }
        uint8_t label = labels ? labels[i] : table ? table[r[cls_at] & cls_mask] : 0;
        soil += label == 0;
        if (c->framed) {
            int64_t col = lattice(p[0], c->plo[0], c->pres, c->pcols);
            int64_t row = lattice(p[1], c->plo[1], c->pres, c->prows);
            if (!c->framed[(row + 1) * (c->pcols + 2) + col + 1]) continue;
        }
        int near = !c->use_box || in_box(p, c->box);
        if (label != 0) {
            if (near) put3f(c->others + 3 * other, p), c->other_labels[other++] = label;
            continue;
        }
        cropped++;
        int64_t ix = column(p[0], c->tlo[0], c->voxel, c->first[0]);
        int64_t iy = column(p[1], c->tlo[1], c->voxel, c->first[1]);
        if ((uint64_t)ix < (uint64_t)c->shape[1] && (uint64_t)iy < (uint64_t)c->shape[0])
            thin_add(c, iy * c->shape[1] + ix, p);
        if (near) put3f(c->out + 3 * kept++, p);
    }
    c->cropped += cropped, c->kept = kept, c->other = other, c->soil += soil;
}

static void chunk_start(sv_chunk_t *c) {
    c->cropped = c->kept = c->other = c->soil = 0;
    for (int k = 0; k < 3; k++) c->lo[k] = INFINITY, c->hi[k] = -INFINITY;
}

/* One piece of a chunk given as records (c->rec, c->n) and labels (c->labels, NULL: all soil);
 * the chunk's column sums are added up when c->flush is set. */
void sv_chunk(sv_chunk_t *c) {
    chunk_start(c);
    chunk_points(c, c->rec, c->n, c->labels, NULL, 0, 0);
    if (c->flush) thin_flush(c);
}

#ifndef _WIN32

/* One whole chunk read from a file: count records from byte offset of the open file fd, into buf
 * (room for room records) piece by piece, labelled by table (the LAS classification at byte
 * cls_at of a record, masked by cls_mask; NULL: all soil); the column sums added up at the end.
 * Returns 0, or -1 when the file ends or a read fails first (errno says which). */
int64_t sv_file_chunk(sv_chunk_t *c, int64_t fd, int64_t offset, int64_t count, uint8_t *buf, int64_t room,
                      const uint8_t *table, int64_t cls_at, int64_t cls_mask) {
    chunk_start(c);
    for (int64_t done = 0; done < count;) {
        int64_t m = count - done < room ? count - done : room, want = m * c->stride, got = 0;
        while (got < want) {
            ssize_t r = pread((int)fd, buf + got, (size_t)(want - got), (off_t)(offset + done * c->stride + got));
            if (r < 0 && errno == EINTR) continue;
            if (r <= 0) return -1;
            got += r;
        }
        chunk_points(c, buf, m, NULL, table, cls_at, cls_mask);
        done += m;
    }
    thin_flush(c);
    return 0;
}
#endif

/* The points whose x/y lie in the box x0..x1, y0..y1, edges included (numpy twin:
 * core.cells.in_box and a compress of each axis): x, y, z step doubles apart; with out NULL
 * counts them, else writes them in order to out (3 rows of m). Returns m. */
int64_t sv_cut_box(const double *x, const double *y, const double *z, int64_t n, int64_t step, double x0,
                   double y0, double x1, double y1, double *out, int64_t m) {
    const double box[4] = {x0, y0, x1, y1};
    int64_t k = 0;
    for (int64_t i = 0; i < n; i++) {
        const double p[2] = {x[i * step], y[i * step]};
        if (in_box(p, box)) {
            if (out) out[k] = p[0], out[m + k] = p[1], out[2 * m + k] = z[i * step];
            k++;
        }
    }
    return k;
}

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

/* Column means on a grid (numpy twin: soilvolume.registration.columns._binned): a point's column
 * floor((v - lo) / cell) per axis (off the grid: dropped), its sums in point order from zero. x, y,
 * z step doubles apart; count (rows * cols) and sums (3 x rows * cols): zeros, left zeros. The
 * occupied columns' ids, in order, to has, their means (m x 3) to means; returns m. */
int64_t sv_columns(const double *x, const double *y, const double *z, int64_t n, int64_t step, double lo0,
                   double lo1, double cell, int64_t rows, int64_t cols, int64_t *count, double *sums,
                   int64_t *has, double *means) {
    int64_t cells = rows * cols, first = cells, last = -1;
    for (int64_t i = 0; i < n; i++) {
        double fx = x[i * step] - lo0, fy = y[i * step] - lo1;
        fx = floor(fx / cell), fy = floor(fy / cell);
        if (!(fx >= 0.0 && fy >= 0.0 && fx < (double)cols && fy < (double)rows)) continue;
        int64_t id = (int64_t)(fy * (double)cols + fx);
        count[id]++;
        sums[id] += x[i * step], sums[cells + id] += y[i * step], sums[2 * cells + id] += z[i * step];
        if (id < first) first = id;
        if (id > last) last = id;
    }
    int64_t m = 0;
    for (int64_t id = first; id <= last; id++) {
        if (!count[id]) continue;
        double c = (double)count[id];
        has[m] = id;
        means[3 * m] = sums[id] / c, means[3 * m + 1] = sums[cells + id] / c, means[3 * m + 2] = sums[2 * cells + id] / c;
        m++;
        count[id] = 0, sums[id] = sums[cells + id] = sums[2 * cells + id] = 0.0;
    }
    return m;
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
        double t = z[i] / q;
        int64_t id = ids[i];
        key[i] = (id << bits) | ((int64_t)rint(t) - base);
        counts[id]++;
    }
}

/* a * a + b * b + c * c, summed in that order (numpy's and scipy's cKDTree's order). */
static inline double sq3(double a, double b, double c) { return a * a + b * b + c * c; }

/* The distance of point i (of n, columns of pts: 3 x n) to target column j (of t: 3 x tn). */
static inline double dist_to(const double *pts, int64_t n, int64_t i, const double *t, int64_t tn, int64_t j) {
    return sqrt(sq3(pts[i] - t[j], pts[n + i] - t[tn + j], pts[2 * n + i] - t[2 * tn + j]));
}

static inline void swap_d(double *a, double *b) {
    double t = *a;
    *a = *b, *b = t;
}

/* Whether the nearest target kept for point i (at: where it was searched from, idx, second: the
 * second-nearest distance) is still proven (registration.icp.Nearest._proven); *d: its distance. */
static inline int proven(const double *pts, int64_t n, int64_t i, const double *at, const int64_t *idx,
                         const double *second, const double *t, int64_t tn, int64_t m, double free, double *d) {
    *d = dist_to(pts, n, i, t, tn, idx[i]);
    double moved = dist_to(pts, n, i, at, n, i);
    moved += 1e-9;
    return idx[i] < m ? *d + moved < second[i] : moved < free;
}

/* The ICP's nearest neighbours kept while a bound proves them (numpy twin: registration.icp.Nearest.
 * __call__ before its k-d tree search): each point's distance to its kept nearest (last: at 3 x n,
 * idx, second) into d; where only the search before (old, when has_old) proves it, the two swap;
 * the others' last search copied to old and their indices to todo. free: the bound less the
 * correspondence distance. Returns the number in todo. */
int64_t sv_nearest_kept(const double *pts, int64_t n, double *last_at, int64_t *last_idx, double *last_second,
                        double *old_at, int64_t *old_idx, double *old_second, int64_t has_old, const double *t,
                        int64_t tn, int64_t m, double free, double *d, int64_t *todo) {
    int64_t k = 0;
    for (int64_t i = 0; i < n; i++) {
        if (proven(pts, n, i, last_at, last_idx, last_second, t, tn, m, free, &d[i])) continue;
        if (has_old) {
            double db;
            if (proven(pts, n, i, old_at, old_idx, old_second, t, tn, m, free, &db)) {
                for (int c = 0; c < 3; c++) swap_d(&last_at[c * n + i], &old_at[c * n + i]);
                swap_d(&last_second[i], &old_second[i]);
                int64_t j = last_idx[i];
                last_idx[i] = old_idx[i], old_idx[i] = j;
                d[i] = db;
                continue;
            }
            for (int c = 0; c < 3; c++) old_at[c * n + i] = last_at[c * n + i];
            old_idx[i] = last_idx[i], old_second[i] = last_second[i];
        }
        todo[k++] = i;
    }
    return k;
}

/* The cell of (x, y) in a grid of nx x ny cells of side g from (x0, y0), clamped to its edge. */
static int64_t grid_cell(double x, double y, double x0, double y0, double g, int64_t nx, int64_t ny) {
    double fx = floor((x - x0) / g), fy = floor((y - y0) / g);
    int64_t cx = fx < 0.0 ? 0 : (fx >= (double)nx ? nx - 1 : (int64_t)fx);
    int64_t cy = fy < 0.0 ? 0 : (fy >= (double)ny ? ny - 1 : (int64_t)fy);
    return cy * nx + cx;
}

/* A bucket grid of target points for nearest-neighbour searches (numpy twin: a scipy cKDTree,
 * registration.icp.tree_of): the m points t (3 x tn rows, x and y used) counted into nx x ny
 * cells of side g from (x0, y0) (clamped to the edge cells), start (nx * ny + 1) the first
 * entry of each cell in order (m), the points of a cell in their own order. */
void sv_grid_build(const double *t, int64_t tn, int64_t m, double x0, double y0, double g, int64_t nx, int64_t ny,
                   int64_t *start, int64_t *order) {
    int64_t cells = nx * ny;
    for (int64_t c = 0; c <= cells; c++) start[c] = 0;
    for (int64_t i = 0; i < m; i++) start[grid_cell(t[i], t[tn + i], x0, y0, g, nx, ny) + 1]++;
    for (int64_t c = 0; c < cells; c++) start[c + 1] += start[c];
    for (int64_t i = 0; i < m; i++) order[start[grid_cell(t[i], t[tn + i], x0, y0, g, nx, ny)]++] = i;
    for (int64_t c = cells; c > 0; c--) start[c] = start[c - 1];
    start[0] = 0;
}

/* The points of the cells of row cy, columns lo..hi: their squared distances to (px, py, pz),
 * each kept when below the two best so far (b1 <= b2, index i1 of the best). */
static void grid_row(const double *t, int64_t tn, const int64_t *start, const int64_t *order, int64_t nx,
                     int64_t cy, int64_t lo, int64_t hi, double px, double py, double pz, double *b1, double *b2,
                     int64_t *i1) {
    for (int64_t c = cy * nx + lo; c <= cy * nx + hi; c++) {
        for (int64_t e = start[c]; e < start[c + 1]; e++) {
            int64_t j = order[e];
            /* cKDTree's unrolled loop adds to 0.0 first: 0.0 + dx * dx is dx * dx */
            double d = sq3(px - t[j], py - t[tn + j], pz - t[2 * tn + j]);
            if (d < *b1) {
                *b2 = *b1, *b1 = d, *i1 = j;
            } else if (d < *b2) {
                *b2 = d;
            }
        }
    }
}

/* For each of the n points p (3 x n rows) its nearest target (index into the grid's points, m
 * when none is nearer than bound) and the distance to the second nearest (bound when none is
 * nearer), as cKDTree.query(k=2, distance_upper_bound=bound) finds them: rings of cells round
 * the point's cell until a ring cannot hold a point nearer than the second found. */
void sv_grid_nearest2(const double *p, int64_t n, const double *t, int64_t tn, int64_t m, double x0, double y0,
                      double g, int64_t nx, int64_t ny, const int64_t *start, const int64_t *order, double bound,
                      int64_t *idx, double *second) {
    double bb = bound * bound, rings = bound / g;
    int64_t rmax = rings < 1e9 ? (int64_t)rings + 2 : 1000000000; /* an unbounded search: the grid's extent bounds it */
    for (int64_t i = 0; i < n; i++) {
        double px = p[i], py = p[n + i], pz = p[2 * n + i];
        double fx = floor((px - x0) / g), fy = floor((py - y0) / g);
        double b1 = bb, b2 = bb;
        int64_t i1 = m;
        if (fx > -(double)rmax && fy > -(double)rmax && fx < (double)(nx + rmax) && fy < (double)(ny + rmax)) {
            int64_t qx = (int64_t)fx, qy = (int64_t)fy;
            /* rings nearer than the grid's nearest cell are empty, none is beyond its farthest:
             * edge holds the point's cell less the grid's first and last column and row */
            int64_t edge[4] = {qx, qx - (nx - 1), qy, qy - (ny - 1)}, near = 0, far = 0;
            for (int a = 0; a < 4; a++) {
                int64_t out = a % 2 ? edge[a] : -edge[a], dist = edge[a] < 0 ? -edge[a] : edge[a];
                if (out > near) near = out;
                if (dist > far) far = dist;
            }
            for (int64_t r = near; r <= rmax && r <= far; r++) {
                double lb = (double)(r - 1) * g;
                if (r > 1 && lb * lb > b2) break;
                int64_t ylo = qy - r < 0 ? 0 : qy - r, yhi = qy + r >= ny ? ny - 1 : qy + r;
                int64_t xlo = qx - r < 0 ? 0 : qx - r, xhi = qx + r >= nx ? nx - 1 : qx + r;
                for (int64_t cy = ylo; cy <= yhi; cy++) {
                    if (cy == qy - r || cy == qy + r) {
                        if (xlo <= xhi) grid_row(t, tn, start, order, nx, cy, xlo, xhi, px, py, pz, &b1, &b2, &i1);
                    } else {
                        if (qx - r >= 0 && qx - r < nx)
                            grid_row(t, tn, start, order, nx, cy, qx - r, qx - r, px, py, pz, &b1, &b2, &i1);
                        if (r > 0 && qx + r >= 0 && qx + r < nx)
                            grid_row(t, tn, start, order, nx, cy, qx + r, qx + r, px, py, pz, &b1, &b2, &i1);
                    }
                }
            }
        }
        idx[i] = i1;
        second[i] = b2 < bb ? sqrt(b2) : bound;
    }
}

/* The terms of one Gauss-Newton step of the Tukey-weighted point-to-plane ICP (numpy twin:
 * registration.icp._step before its matrix products): for the K points pts[:, sel] (pts: 3 x n)
 * and their targets t[:, j] (3 x tn) with normals nrm[:, j] (3 x nn), the residuals r, the
 * Jacobian rows jac (6 x K: p x n, then n) and the weighted rows jw = jac * w. */
void sv_icp_terms(const double *pts, int64_t n, const int64_t *sel, const int64_t *j, int64_t K, const double *t,
                  int64_t tn, const double *nrm, int64_t nn, double k, double *jac, double *jw, double *r) {
    for (int64_t i = 0; i < K; i++) {
        int64_t s = sel[i], c = j[i];
        double p0 = pts[s], p1 = pts[n + s], p2 = pts[2 * n + s];
        double n0 = nrm[c], n1 = nrm[nn + c], n2 = nrm[2 * nn + c];
        double res = (p0 - t[c]) * n0 + (p1 - t[tn + c]) * n1 + (p2 - t[2 * tn + c]) * n2;
        double u = 1.0 - (res / k) * (res / k);
        u *= u;
        double w = fabs(res) <= k ? u : 0.0;
        double row[6] = {p1 * n2 - p2 * n1, p2 * n0 - p0 * n2, p0 * n1 - p1 * n0, n0, n1, n2};
        for (int q = 0; q < 6; q++) {
            jac[q * K + i] = row[q];
            jw[q * K + i] = row[q] * w;
        }
        r[i] = res;
    }
}

/* The centroids of a thinning lattice's occupied columns (numpy twin: ColumnThinner.result and
 * counts): for each column with a count (sums: x, y, z, count rows of ncols), in order, its sums
 * over its count into out (m x 3; NULL: not wanted) and the count into counts. Returns m. */
int64_t sv_centroids(const double *sums, int64_t ncols, double *out, int64_t *counts) {
    const double *sx = sums, *sy = sums + ncols, *sz = sums + 2 * ncols, *sc = sums + 3 * ncols;
    int64_t m = 0;
    for (int64_t j = 0; j < ncols; j++) {
        double c = sc[j];
        if (!(c > 0.0)) continue;
        if (out) out[3 * m] = sx[j] / c, out[3 * m + 1] = sy[j] / c, out[3 * m + 2] = sz[j] / c;
        counts[m++] = (int64_t)c;
    }
    return m;
}
