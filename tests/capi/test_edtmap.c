/* The C API against an analytic wall, the Rust Mapper (bit for bit), its
 * own saved map, every error path, and queries running while another
 * thread integrates. Built against the installed package
 * (tests/capi/CMakeLists.txt), run by tests/capi/run.sh, also under
 * valgrind.
 *
 *   test_edtmap_c REFERENCE.bin TMPDIR */
/* nanosleep under -std=c11. */
#define _POSIX_C_SOURCE 200809L

#include <edtmap.h>

#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "wall.h"

#define CHECK(cond, ...)                                                   \
    do {                                                                   \
        if (!(cond)) {                                                     \
            fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                  \
            fprintf(stderr, "\n");                                         \
            exit(1);                                                       \
        }                                                                  \
    } while (0)

#define OK(call) CHECK((call) == EDTMAP_OK, "%s", edtmap_last_error())

/* A call that must fail with `status` and say something naming `word`. */
#define FAILS(call, status, word)                                                                    \
    do {                                                                                             \
        edtmap_status got_ = (call);                                                                 \
        CHECK(got_ == (status), "status %d, expected %d (%s)", (int)got_, (int)(status), edtmap_last_error()); \
        CHECK(strstr(edtmap_last_error(), (word)) != NULL, "message \"%s\" lacks \"%s\"", edtmap_last_error(), (word)); \
    } while (0)

static float cloud[3 * WALL_POINTS];

/* Fails a call on its own thread and returns whether that thread's message
 * names it. */
static void* fail_elsewhere(void* arg) {
    (void)arg;
    int named = edtmap_map_load(NULL, NULL) == EDTMAP_NULL_ARGUMENT && strstr(edtmap_last_error(), "edtmap_map_load") != NULL;
    return named ? arg : NULL;
}

struct reader {
    edtmap_mapper* mapper;
    volatile int* stop;
    volatile long queries;
    int failures;
};

/* Queries the wall's centre line until told to stop. */
static void* read_loop(void* arg) {
    struct reader* r = arg;
    double pts[3 * 20], d[20];
    for (int i = 0; i < 20; ++i) {
        pts[3 * i] = 0.05 + 0.1 * i;
        pts[3 * i + 1] = 0.05;
        pts[3 * i + 2] = 0.05;
    }
    while (!*r->stop) {
        if (edtmap_mapper_query(r->mapper, pts, 20, false, d, NULL, NULL) != EDTMAP_OK) {
            r->failures++;
        }
        /* Every answer is a whole frame's: the wall is 2 m away or more. */
        for (int i = 0; i < 20; ++i) {
            if (!(d[i] >= 0.0 && d[i] <= 2.0 + 1e-9)) {
                r->failures++;
            }
        }
        r->queries++;
    }
    return NULL;
}

int main(int argc, char** argv) {
    CHECK(argc == 3, "usage: test_edtmap_c REFERENCE.bin TMPDIR");
    char path[4096];
    printf("edtmap %s\n", edtmap_version());

    edtmap_params p;
    OK(edtmap_params_default(&p));
    edtmap_mapper* m = NULL;
    OK(edtmap_mapper_new(&p, &m));
    wall_cloud(cloud);
    edtmap_frame_stats st;
    OK(edtmap_integrate_points(m, cloud, WALL_POINTS, WALL_IDENTITY, 0.0, &st));
    CHECK(st.voxels_updated > 0 && st.edt_voxels_changed > 0, "updated %llu", (unsigned long long)st.voxels_updated);

    /* The analytic wall: voxel centres on the centre line, the wall in
     * voxel x = 20 (2.0 to 2.1 m). */
    for (int i = 5; i < 20; ++i) {
        double q[3] = {(i + 0.5) * 0.1, 0.05, 0.05}, d, g[3];
        uint8_t s;
        OK(edtmap_mapper_query(m, q, 1, false, &d, g, &s));
        CHECK(fabs(d - (20 - i) * 0.1) < 1e-9, "voxel %d: distance %.17g", i, d);
        CHECK(fabs(g[0] + 1.0) < 1e-9 && fabs(g[1]) < 1e-9 && fabs(g[2]) < 1e-9, "voxel %d: gradient %g %g %g", i, g[0], g[1], g[2]);
        /* The voxel before the wall lies within the free margin of the returns. */
        CHECK(s == (i < 19 ? EDTMAP_STATE_FREE : EDTMAP_STATE_UNKNOWN), "voxel %d: state %d", i, s);
    }
    {
        double q[3] = {2.05, 0.05, 0.05}, d;
        uint8_t s;
        OK(edtmap_mapper_query(m, q, 1, true, &d, NULL, &s));
        CHECK(s == EDTMAP_STATE_OCCUPIED && d < 0.0, "wall voxel: state %d, signed distance %g", s, d);
    }

    /* The Rust Mapper's answers, bit for bit. */
    static double qp[3 * WALL_QUERIES], d[WALL_QUERIES], g[3 * WALL_QUERIES], rd[WALL_QUERIES], rg[3 * WALL_QUERIES];
    static uint8_t s[WALL_QUERIES], rs[WALL_QUERIES];
    wall_queries(qp);
    OK(edtmap_mapper_query(m, qp, WALL_QUERIES, false, d, g, s));
    CHECK(wall_reference(argv[1], rd, rg, rs) == 0, "cannot read %s", argv[1]);
    CHECK(memcmp(d, rd, sizeof d) == 0, "distances differ from the Rust Mapper's");
    CHECK(memcmp(g, rg, sizeof g) == 0, "gradients differ from the Rust Mapper's");
    CHECK(memcmp(s, rs, sizeof s) == 0, "states differ from the Rust Mapper's");

    /* Save, load, the same answers. */
    snprintf(path, sizeof path, "%s/wall.edtmap", argv[2]);
    OK(edtmap_mapper_save(m, path));
    edtmap_map* map = NULL;
    OK(edtmap_map_load(path, &map));
    CHECK(fabs(edtmap_map_voxel_size(map) - 0.1) < 1e-12 && fabs(edtmap_map_max_distance(map) - 2.0) < 1e-12, "map parameters");
    static double md[WALL_QUERIES], mg[3 * WALL_QUERIES];
    static uint8_t ms[WALL_QUERIES];
    OK(edtmap_map_query(map, qp, WALL_QUERIES, false, md, mg, ms));
    CHECK(memcmp(d, md, sizeof d) == 0 && memcmp(g, mg, sizeof g) == 0 && memcmp(s, ms, sizeof s) == 0, "loaded map answers differently");

    /* A dense box: size first, then the values. */
    double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {2.2, 0.3, 0.2};
    edtmap_box info;
    OK(edtmap_map_export_box(map, lo, hi, false, NULL, NULL, 0, &info));
    size_t n = (size_t)(info.dims[0] * info.dims[1] * info.dims[2]);
    CHECK(info.dims[0] == 22 && info.dims[1] == 3 && info.dims[2] == 2, "box dims %llu %llu %llu", (unsigned long long)info.dims[0],
          (unsigned long long)info.dims[1], (unsigned long long)info.dims[2]);
    float* bd = malloc(n * sizeof *bd);
    uint8_t* bs = malloc(n);
    FAILS(edtmap_map_export_box(map, lo, hi, false, bd, bs, n - 1, &info), EDTMAP_INVALID_ARGUMENT, "capacity");
    OK(edtmap_map_export_box(map, lo, hi, false, bd, bs, n, &info));
    CHECK(fabsf(bd[10] - 1.0f) < 1e-6f && bs[20] == EDTMAP_STATE_OCCUPIED, "box values %g %d", bd[10], bs[20]);
    free(bd);
    free(bs);

    /* Errors: each with its status and a message naming the problem. */
    double q1[3] = {1, 0, 0}, d1;
    FAILS(edtmap_mapper_query(NULL, q1, 1, false, &d1, NULL, NULL), EDTMAP_NULL_ARGUMENT, "mapper is null");
    FAILS(edtmap_mapper_query(m, q1, 1, false, NULL, NULL, NULL), EDTMAP_NULL_ARGUMENT, "distances is null");
    FAILS(edtmap_mapper_query(m, NULL, 1, false, &d1, NULL, NULL), EDTMAP_NULL_ARGUMENT, "points is null");
    {
        double buf[8];
        const double* odd = (const double*)((const char*)buf + 1);
        FAILS(edtmap_mapper_query(m, odd, 1, false, &d1, NULL, NULL), EDTMAP_INVALID_ARGUMENT, "aligned");
    }
    FAILS(edtmap_integrate_points(m, cloud, SIZE_MAX, WALL_IDENTITY, 1.0, NULL), EDTMAP_INVALID_ARGUMENT, "n_points");
    FAILS(edtmap_integrate_points(NULL, cloud, 10, WALL_IDENTITY, 1.0, NULL), EDTMAP_NULL_ARGUMENT, "mapper is null");
    {
        double nan_pose[16];
        memcpy(nan_pose, WALL_IDENTITY, sizeof nan_pose);
        nan_pose[3] = NAN;
        FAILS(edtmap_integrate_points(m, cloud, WALL_POINTS, nan_pose, 1.0, NULL), EDTMAP_INVALID_ARGUMENT, "finite");
        double scaled[16];
        memcpy(scaled, WALL_IDENTITY, sizeof scaled);
        scaled[0] = 2.0;
        FAILS(edtmap_integrate_points(m, cloud, WALL_POINTS, scaled, 1.0, NULL), EDTMAP_INVALID_ARGUMENT, "t_world_sensor");
        /* Published ground truth: orthonormal only to about 2e-4; taken
         * as its nearest rotation, the wall maps where the exact pose
         * maps it. A 2 % scale is not a rotation. */
        double published[16];
        memcpy(published, WALL_IDENTITY, sizeof published);
        published[0] += 1e-4;
        published[1] -= 1e-4;
        published[6] += 1e-4;
        edtmap_mapper* pm = NULL;
        OK(edtmap_mapper_new(&p, &pm));
        OK(edtmap_integrate_points(pm, cloud, WALL_POINTS, published, 1.0, NULL));
        for (int i = 5; i < 20; ++i) {
            const double probe[3] = {(i + 0.5) * 0.1, 0.05, 0.05};
            double pd = 0.0;
            OK(edtmap_mapper_query(pm, probe, 1, false, &pd, NULL, NULL));
            CHECK(fabs(pd - (20 - i) * 0.1) < 1e-9, "published pose, voxel %d: distance %.17g", i, pd);
        }
        published[0] = 1.02;
        FAILS(edtmap_integrate_points(pm, cloud, WALL_POINTS, published, 1.0, NULL), EDTMAP_INVALID_ARGUMENT, "not orthonormal");
        edtmap_mapper_free(pm);
    }
    {
        float depth[4] = {1, 1, 1, 1};
        FAILS(edtmap_integrate_depth(m, depth, 2, 2, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        float ranges[3] = {1, 1, 1};
        FAILS(edtmap_integrate_scan(m, ranges, 3, 0.0, 0.1, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        uint16_t raw[4] = {1000, 1000, 1000, 1000};
        FAILS(edtmap_integrate_depth_u16(m, raw, 2, 2, -1.0f, WALL_IDENTITY, 1.0, NULL), EDTMAP_INVALID_ARGUMENT, "metres_per_unit");
    }
    snprintf(path, sizeof path, "%s/corrupt.edtmap", argv[2]);
    {
        FILE* f = fopen(path, "wb");
        CHECK(f != NULL, "cannot write %s", path);
        fputs("not a map at all", f);
        fclose(f);
    }
    edtmap_map* bad = NULL;
    FAILS(edtmap_map_load(path, &bad), EDTMAP_IO, "corrupt.edtmap");
    CHECK(bad == NULL, "a failed load gave a handle");
    FAILS(edtmap_map_load(NULL, &bad), EDTMAP_NULL_ARGUMENT, "path is null");
    snprintf(path, sizeof path, "%s/missing.toml", argv[2]);
    edtmap_mapper* none = NULL;
    FAILS(edtmap_mapper_from_config(path, EDTMAP_BACKEND_CPU, &none), EDTMAP_IO, "missing.toml");
    {
        edtmap_params q = p;
        q.voxel_size_m = -1.0;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_CONFIG, "voxel_size_m");
        q = p;
        q.voxel_size_m = NAN;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_CONFIG, "voxel_size_m");
    }
    /* Enumerations and flags are numbers in C: one out of range is refused,
     * naming the field and the values it takes. */
    {
        edtmap_params q = p;
        q.sensor = 42;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_INVALID_ARGUMENT, "edtmap_params.sensor = 42");
        CHECK(strstr(edtmap_last_error(), "EDTMAP_SENSOR_PLANAR (3)") != NULL, "%s", edtmap_last_error());
        q.sensor = UINT32_MAX;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_INVALID_ARGUMENT, "edtmap_params.sensor = 4294967295");
        q = p;
        q.backend = 7;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_INVALID_ARGUMENT, "edtmap_params.backend = 7");
        CHECK(strstr(edtmap_last_error(), "EDTMAP_BACKEND_AUTO (2)") != NULL, "%s", edtmap_last_error());
        q = p;
        q.exact = 0x7f;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_INVALID_ARGUMENT, "edtmap_params.exact = 127: must be 0 (false) or 1 (true)");
        q = p;
        q.clear_no_return = 2;
        FAILS(edtmap_mapper_new(&q, &none), EDTMAP_INVALID_ARGUMENT, "edtmap_params.clear_no_return = 2");
        FAILS(edtmap_mapper_from_config(path, 7, &none), EDTMAP_INVALID_ARGUMENT, "backend = 7");
        FAILS(edtmap_mapper_resume(path, path, 3, &none), EDTMAP_INVALID_ARGUMENT, "backend = 3");
        /* Every value in range is taken. */
        q = p;
        q.exact = 0;
        q.clear_no_return = 1;
        q.backend = EDTMAP_BACKEND_AUTO;
        edtmap_mapper* wavefront = NULL;
        OK(edtmap_mapper_new(&q, &wavefront));
        edtmap_mapper_free(wavefront);
    }
    CHECK(none == NULL, "a failed constructor gave a handle");

    /* A null out-pointer is refused before anything is built: under
     * valgrind and ASan, a handle built and then dropped would show as a
     * leak. Each call would otherwise succeed. */
    {
        char config[4096], saved[4096];
        snprintf(config, sizeof config, "%s/points.toml", argv[2]);
        FILE* f = fopen(config, "w");
        CHECK(f != NULL, "cannot write %s", config);
        fputs("[sensor]\nkind = \"points\"\nmin_range_m = 0.3\nmax_range_m = 10.0\n[occupancy]\nvoxel_size_m = 0.1\nlocal_size_m = [10.0, 10.0, 4.0]\n[global]\nmax_distance_m = 2.0\n", f);
        fclose(f);
        snprintf(saved, sizeof saved, "%s/wall.edtmap", argv[2]);
        FAILS(edtmap_mapper_new(&p, NULL), EDTMAP_NULL_ARGUMENT, "out is null");
        FAILS(edtmap_mapper_from_config(config, EDTMAP_BACKEND_CPU, NULL), EDTMAP_NULL_ARGUMENT, "out is null");
        FAILS(edtmap_mapper_resume(config, saved, EDTMAP_BACKEND_CPU, NULL), EDTMAP_NULL_ARGUMENT, "out is null");
        FAILS(edtmap_map_load(saved, NULL), EDTMAP_NULL_ARGUMENT, "out is null");
        FAILS(edtmap_params_default(NULL), EDTMAP_NULL_ARGUMENT, "out is null");
        edtmap_mapper* resumed = NULL;
        OK(edtmap_mapper_resume(config, saved, EDTMAP_BACKEND_CPU, &resumed));
        OK(edtmap_mapper_query(resumed, qp, WALL_QUERIES, false, md, NULL, NULL));
        CHECK(memcmp(d, md, sizeof d) == 0, "the resumed map answers differently");
        edtmap_mapper_free(resumed);
        OK(edtmap_mapper_from_config(config, EDTMAP_BACKEND_CPU, &resumed));
        edtmap_mapper_free(resumed);
    }

    /* Empty inputs: a batch of 0 points is an answer of size 0, null
     * buffers and all; an empty frame reaches the mapper, which refuses it
     * (it observes nothing), whether its buffer is null or not. */
    {
        double sentinel = 42.0;
        OK(edtmap_mapper_query(m, NULL, 0, false, NULL, NULL, NULL));
        OK(edtmap_map_query(map, NULL, 0, true, NULL, NULL, NULL));
        OK(edtmap_mapper_query(m, q1, 0, false, &sentinel, NULL, NULL));
        CHECK(sentinel == 42.0, "a query of 0 points wrote %g", sentinel);
        FAILS(edtmap_integrate_points(m, NULL, 0, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "point cloud is empty");
        FAILS(edtmap_integrate_points(m, cloud, 0, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "point cloud is empty");
        FAILS(edtmap_integrate_scan(m, NULL, 0, 0.0, 0.1, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        edtmap_params planar_params = p;
        planar_params.sensor = EDTMAP_SENSOR_PLANAR;
        edtmap_mapper* planar = NULL;
        OK(edtmap_mapper_new(&planar_params, &planar));
        FAILS(edtmap_integrate_scan(planar, NULL, 0, 0.0, 0.1, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "no ranges");
        edtmap_mapper_free(planar);
        FAILS(edtmap_integrate_range_image(m, NULL, 0, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        FAILS(edtmap_integrate_depth(m, NULL, 0, 0, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        FAILS(edtmap_integrate_depth_u16(m, NULL, 0, 480, 0.001f, WALL_IDENTITY, 1.0, NULL), EDTMAP_FRAME, "");
        /* Null with a length is still a caller's mistake. */
        FAILS(edtmap_integrate_points(m, NULL, 1, WALL_IDENTITY, 1.0, NULL), EDTMAP_NULL_ARGUMENT, "xyz is null");
        FAILS(edtmap_integrate_depth(m, NULL, 2, 2, WALL_IDENTITY, 1.0, NULL), EDTMAP_NULL_ARGUMENT, "depth_m is null");
    }
    /* The last error's lifetime, as the header states it: the message stays
     * at its address through successful calls and other threads' failures,
     * until this thread's next failure. */
    {
        FAILS(edtmap_mapper_query(NULL, q1, 1, false, &d1, NULL, NULL), EDTMAP_NULL_ARGUMENT, "mapper is null");
        const char* msg = edtmap_last_error();
        char copy[256];
        snprintf(copy, sizeof copy, "%s", msg);
        OK(edtmap_mapper_query(m, q1, 1, false, &d1, NULL, NULL));
        pthread_t other;
        void* named = NULL;
        int token = 0;
        CHECK(pthread_create(&other, NULL, fail_elsewhere, &token) == 0, "pthread_create");
        pthread_join(other, &named);
        CHECK(named == &token, "the other thread's message does not name its call");
        CHECK(edtmap_last_error() == msg && strcmp(msg, copy) == 0, "the message changed: \"%s\"", edtmap_last_error());
    }
    /* The map is as it was after all of that. */
    OK(edtmap_mapper_query(m, qp, WALL_QUERIES, false, md, NULL, NULL));
    CHECK(memcmp(d, md, sizeof d) == 0, "refused frames changed the map");

    /* Four threads query while this one integrates. */
    volatile int stop = 0;
    struct reader readers[4];
    pthread_t threads[4];
    for (int k = 0; k < 4; ++k) {
        readers[k] = (struct reader){m, &stop, 0, 0};
        CHECK(pthread_create(&threads[k], NULL, read_loop, &readers[k]) == 0, "pthread_create");
    }
    /* Every reader is querying before the frames start (a loaded machine,
     * or a sanitizer build, starts threads late). */
    for (int k = 0, waited_ms = 0; k < 4; ++k) {
        while (readers[k].queries == 0 && waited_ms < 60000) {
            struct timespec ms = {0, 1000000};
            nanosleep(&ms, NULL);
            ++waited_ms;
        }
        CHECK(readers[k].queries > 0, "reader %d never ran a query", k);
    }
    for (int f = 1; f <= 6; ++f) {
        double pose[16];
        memcpy(pose, WALL_IDENTITY, sizeof pose);
        pose[7] = 0.01 * f; /* a little sideways each frame */
        OK(edtmap_integrate_points(m, cloud, WALL_POINTS, pose, (double)f, NULL));
    }
    stop = 1;
    long total = 0;
    for (int k = 0; k < 4; ++k) {
        pthread_join(threads[k], NULL);
        CHECK(readers[k].failures == 0, "reader %d: %d failures", k, readers[k].failures);
        total += readers[k].queries;
    }
    CHECK(total > 0, "no query ran");

    edtmap_map_free(map);
    edtmap_mapper_free(m);
    edtmap_mapper_free(NULL);
    edtmap_map_free(NULL);
    printf("C API: all checks passed (%ld concurrent queries)\n", total);
    return 0;
}
