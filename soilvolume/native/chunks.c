/* A cloud's chunks of point records streamed into the working frame; a thinning lattice's centroids. */
#include "kernels.h"
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
            int32_t v;
            memcpy(&v, r + c->field[k], 4); /* unaligned */
            double t = (double)v * c->scale[k];
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
