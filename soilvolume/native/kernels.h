/* soilvolume's native kernels: loops numpy runs as many passes over memory, in one pass each, in
 * chunks.c (a cloud's chunks read), cells.c (points to grid cells, their keys and their sort) and
 * registration.c (the registration's cuts, column means, neighbours and ICP step). Plain C99 loaded
 * with ctypes (the GIL released for the call). Each kernel does its numpy twin's (named in its
 * comment) double operations in the same order, built with -ffp-contract=off: a run gives the same
 * bits with or without it (tests/test_native.py). */
#pragma once
#define _POSIX_C_SOURCE 200809L /* pread */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static inline int in_box(const double *p, const double *box) {
    return p[0] >= box[0] && p[0] <= box[2] && p[1] >= box[1] && p[1] <= box[3];
}
