/* The wall scene of the C and C++ API tests, the same as
 * crates/capi/examples/wall_reference.rs computes in Rust: a wall at
 * x = 2.05 m (the middle of voxel 20) seen by a point sensor at the origin, and the query points. */
#ifndef EDTMAP_TEST_WALL_H
#define EDTMAP_TEST_WALL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#define WALL_POINTS (150 * 100)
#define WALL_QUERIES 200

static const double WALL_IDENTITY[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

/* 3 WALL_POINTS floats. */
static void wall_cloud(float* xyz) {
    size_t k = 0;
    for (int iz = 0; iz < 100; ++iz) {
        for (int iy = 0; iy < 150; ++iy) {
            xyz[k++] = 2.05f;
            xyz[k++] = (float)(-1.5 + 0.02 * (double)iy + 0.01);
            xyz[k++] = (float)(-1.0 + 0.02 * (double)iz + 0.01);
        }
    }
}

/* 3 WALL_QUERIES doubles. */
static void wall_queries(double* xyz) {
    for (int i = 0; i < WALL_QUERIES; ++i) {
        xyz[3 * i] = -0.5 + 0.0137 * (double)i;
        xyz[3 * i + 1] = 0.05 + 0.003 * (double)i;
        xyz[3 * i + 2] = 0.05 - 0.002 * (double)i;
    }
}

/* The Rust Mapper's answers (wall_reference's file): 0 on success. */
static int wall_reference(const char* path, double* distances, double* gradients, uint8_t* states) {
    FILE* f = fopen(path, "rb");
    if (!f) {
        return -1;
    }
    uint64_t n = 0;
    int ok = fread(&n, 8, 1, f) == 1 && n == WALL_QUERIES && fread(distances, 8, WALL_QUERIES, f) == WALL_QUERIES &&
             fread(gradients, 8, 3 * WALL_QUERIES, f) == 3 * WALL_QUERIES && fread(states, 1, WALL_QUERIES, f) == WALL_QUERIES;
    fclose(f);
    return ok ? 0 : -1;
}

#endif
