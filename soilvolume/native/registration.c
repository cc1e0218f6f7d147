/* The registration's target cuts, column means, nearest neighbours and ICP step terms. */
#include "kernels.h"

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

/* Column means on a grid (numpy twin: soilvolume.registration.columns._binned): a point's column
 * floor((v - lo) / cell) per axis (off the grid: dropped), its sums in point order from zero. x, y,
 * z step doubles apart; count (rows * cols) and sums (3 x rows * cols): zeros, left zeros. The
 * occupied columns' ids, in order, to has, their means (m x 3) to means; returns m. */
int64_t sv_columns(const double *x, const double *y, const double *z, int64_t n, int64_t step, double lo0,
                   double lo1, double cell, int64_t rows, int64_t cols, int64_t *count, double *sums,
                   int64_t *has, double *means) {
    int64_t cells = rows * cols, first = cells, last = -1;
    for (int64_t i = 0; i < n; i++) {
        double fx = floor((x[i * step] - lo0) / cell), fy = floor((y[i * step] - lo1) / cell);
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
    double moved = dist_to(pts, n, i, at, n, i) + 1e-9;
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
    for (int64_t i = 0; i < m; i++) start[grid_cell(t[i], t[tn + i], x0, y0, g, nx, ny)]++;
    for (int64_t c = 1; c <= cells; c++) start[c] += start[c - 1]; /* the end of each cell */
    for (int64_t i = m - 1; i >= 0; i--) order[--start[grid_cell(t[i], t[tn + i], x0, y0, g, nx, ny)]] = i;
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
            if (d < *b1)
                *b2 = *b1, *b1 = d, *i1 = j;
            else if (d < *b2)
                *b2 = d;
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
