#define _POSIX_C_SOURCE 199309L
/* The C side of bench/capi.sh: the wall, frames and query batches of
 * crates/capi/examples/query_bench.rs through the C API. Prints
 * `c <what> <batch> <ns per point> <ns per call>` lines. */
#include <edtmap.h>

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

#define CHECK(call)                                                 \
    do {                                                            \
        if ((call) != EDTMAP_OK) {                                  \
            fprintf(stderr, "%s: %s\n", #call, edtmap_last_error()); \
            return 1;                                               \
        }                                                           \
    } while (0)

int main(void) {
    edtmap_params p;
    CHECK(edtmap_params_default(&p));
    edtmap_mapper* m = NULL;
    CHECK(edtmap_mapper_new(&p, &m));
    const size_t n_cloud = 300 * 200;
    float* cloud = malloc(3 * n_cloud * sizeof *cloud);
    size_t k = 0;
    for (int iz = 0; iz < 200; ++iz) {
        for (int iy = 0; iy < 300; ++iy) {
            cloud[k++] = 2.05f;
            cloud[k++] = (float)(-3.0 + 0.02 * (double)iy + 0.01);
            cloud[k++] = (float)(-2.0 + 0.02 * (double)iz + 0.01);
        }
    }
    const int frames = 20;
    double t = now_ns();
    for (int f = 0; f < frames; ++f) {
        double pose[16] = {1, 0, 0, 0, 0, 1, 0, 0.02 * f, 0, 0, 1, 0, 0, 0, 0, 1};
        CHECK(edtmap_integrate_points(m, cloud, n_cloud, pose, (double)f, NULL));
    }
    double per_frame = (now_ns() - t) / frames;
    printf("c integrate %zu %.1f %.0f\n", n_cloud, per_frame / (double)n_cloud, per_frame);

    const size_t total = 1000000;
    double* pts = malloc(3 * total * sizeof *pts);
    uint64_t s = 12345;
    for (size_t i = 0; i < 3 * total; i += 3) {
        double r[3];
        for (int a = 0; a < 3; ++a) {
            s = s * 6364136223846793005ULL + 1442695040888963407ULL;
            r[a] = (double)(s >> 11) / (double)(1ULL << 53);
        }
        pts[i] = -1.0 + 4.0 * r[0];
        pts[i + 1] = -3.0 + 6.0 * r[1];
        pts[i + 2] = -2.0 + 4.0 * r[2];
    }
    double* d = malloc(total * sizeof *d);
    double* g = malloc(3 * total * sizeof *g);
    size_t batches[3] = {1, 1000, 1000000};
    for (int b = 0; b < 3; ++b) {
        size_t batch = batches[b];
        size_t calls = 2000000 / batch;
        if (calls < 3) calls = 3;
        if (calls > 200000) calls = 200000;
        double sink = 0.0;
        t = now_ns();
        for (size_t c = 0; c < calls; ++c) {
            size_t start = (c * batch) % (total - batch + 1);
            /* Distances and gradients, as the Rust API returns both. */
            CHECK(edtmap_mapper_query(m, pts + 3 * start, batch, false, d, g, NULL));
            sink += d[batch / 2];
        }
        double per_call = (now_ns() - t) / (double)calls;
        printf("c query %zu %.2f %.0f\n", batch, per_call / (double)batch, per_call);
        if (sink == 12345.678) printf("?\n");
    }
    free(cloud);
    free(pts);
    free(d);
    free(g);
    edtmap_mapper_free(m);
    return 0;
}
