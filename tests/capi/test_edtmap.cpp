// The C++ wrapper (edtmap.hpp) against the analytic wall, the Rust Mapper
// (bit for bit), a saved map, and its exceptions. Built against the
// installed package (tests/capi/CMakeLists.txt), run by tests/capi/run.sh.
//
//   test_edtmap_cpp REFERENCE.bin TMPDIR
#include <edtmap.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <unistd.h>

#include "wall.h"

#define CHECK(cond, msg)                                                               \
    do {                                                                               \
        if (!(cond)) {                                                                 \
            std::fprintf(stderr, "FAIL %s:%d: %s: %s\n", __FILE__, __LINE__, #cond, msg); \
            std::exit(1);                                                              \
        }                                                                              \
    } while (0)

// Runs `f`, which must throw edtmap::Error with `status` and a message
// holding `word`.
template <class F>
void throws(F f, edtmap_status status, const char* what, const char* word = "") {
    try {
        f();
    } catch (const edtmap::Error& e) {
        CHECK(e.status() == status, e.what());
        CHECK(std::strlen(e.what()) > 0, what);
        CHECK(std::strstr(e.what(), word) != nullptr, e.what());
        return;
    }
    CHECK(false, what);
}

// The README's example (checked against this by .ci/check_docs.py), run
// from the repository root: a wall 1.5 m ahead of a 640 x 480 camera.
static void readme_example() {
    std::vector<float> image(640 * 480, 1.5f);
    const float* depth_m = image.data();
    edtmap::Pose T_world_sensor = edtmap::identity_pose();
    double stamp = 0.0;
    // ANCHOR: readme
    edtmap::Mapper mapper = edtmap::Mapper::from_config("configs/ros2_depth.toml");
    mapper.integrate_depth(depth_m, 640, 480, T_world_sensor, stamp);   // row-major 4x4 pose
    edtmap::Point grad;
    double d = mapper.distance({0.0, 0.0, 1.0}, &grad);                 // metres
    // ANCHOR_END: readme
    CHECK(std::fabs(d - 0.5) < 0.1 && grad[2] < -0.9, "the README's example: 0.5 m from the wall");
}

// docs/c-cpp.md's example (checked by .ci/check_docs.py), run in `dir`:
// a wall 1.5 m ahead.
static void book_example(const char* dir) {
    CHECK(chdir(dir) == 0, "chdir");
    std::vector<float> image(640 * 480, 1.5f);
    const float* depth_m = image.data();
    edtmap::Pose T_world_sensor = edtmap::identity_pose();
    double stamp = 0.0;
    const std::size_t n = 2;
    const double xyz[3 * n] = {0.0, 0.0, 0.5, 0.0, 0.0, 1.4};
    double dist[n], grads[3 * n];
    std::uint8_t states[n];
    // ANCHOR: cpp
    edtmap::Params p;                        // defaults; set the sensor, voxel size, ...
    p.sensor = EDTMAP_SENSOR_DEPTH; p.voxel_size_m = 0.05;
    edtmap::Mapper mapper(p);                // or Mapper::from_config("configs/ros2_depth.toml")
    mapper.integrate_depth(depth_m, 640, 480, T_world_sensor, stamp);   // row-major 4x4
    edtmap::Point grad;
    double d = mapper.distance({1.0, 2.0, 0.5}, &grad);                 // metres
    mapper.query(xyz, n, dist, grads, states);       // n points into your buffers, in parallel
    mapper.save("map.edtmap");
    edtmap::Map map = edtmap::Map::load("map.edtmap");                   // queries only
    // ANCHOR_END: cpp
    CHECK(std::isfinite(d) && dist[0] > dist[1] && std::fabs(dist[1] - 0.125) < 1e-9, "c-cpp.md's example");
    CHECK(states[0] == EDTMAP_STATE_FREE && map.query({{0.0, 0.0, 0.5}}).distances[0] == dist[0], "c-cpp.md's example");
}

int main(int argc, char** argv) {
    CHECK(argc == 3, "usage: test_edtmap_cpp REFERENCE.bin TMPDIR");
    readme_example();
    edtmap::Params p;
    CHECK(p.voxel_size_m == 0.1 && p.sensor == EDTMAP_SENSOR_POINTS, "defaults");
    edtmap::Mapper mapper(p);
    std::vector<float> flat(3 * WALL_POINTS);
    wall_cloud(flat.data());
    std::vector<std::array<float, 3>> cloud(WALL_POINTS);
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        cloud[i] = {flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]};
    }
    edtmap::FrameStats st = mapper.integrate_points(cloud, edtmap::identity_pose(), 0.0);
    CHECK(st.voxels_updated > 0, "frame");

    for (int i = 5; i < 19; ++i) {
        edtmap::Point g{};
        double d = mapper.distance({(i + 0.5) * 0.1, 0.05, 0.05}, &g);
        CHECK(std::fabs(d - (20 - i) * 0.1) < 1e-9, "analytic distance");
        CHECK(std::fabs(g[0] + 1.0) < 1e-9 && std::fabs(g[1]) < 1e-9, "analytic gradient");
        CHECK(mapper.state({(i + 0.5) * 0.1, 0.05, 0.05}) == EDTMAP_STATE_FREE, "state");
    }

    std::vector<double> q(3 * WALL_QUERIES);
    wall_queries(q.data());
    std::vector<edtmap::Point> points(WALL_QUERIES);
    for (std::size_t i = 0; i < points.size(); ++i) {
        points[i] = {q[3 * i], q[3 * i + 1], q[3 * i + 2]};
    }
    edtmap::QueryResult r = mapper.query(points);
    std::vector<double> rd(WALL_QUERIES), rg(3 * WALL_QUERIES);
    std::vector<uint8_t> rs(WALL_QUERIES);
    CHECK(wall_reference(argv[1], rd.data(), rg.data(), rs.data()) == 0, "reference file");
    CHECK(r.distances == rd && r.gradients == rg && r.states == rs, "answers differ from the Rust Mapper's");
    CHECK(mapper.distances(points) == rd, "distances()");

    std::string path = std::string(argv[2]) + "/wall_cpp.edtmap";
    mapper.save(path);
    edtmap::Map map = edtmap::Map::load(path);
    CHECK(map.query(points).distances == rd, "loaded map");
    edtmap::DenseBox box = map.export_box({0.0, 0.0, 0.0}, {2.2, 0.3, 0.2});
    CHECK(box.info.dims[0] == 22 && box.distances.size() == 22 * 3 * 2, "box");
    edtmap::Map copy = map;  // maps share one immutable handle
    CHECK(copy.voxel_size() == 0.1 && copy.max_distance() == 2.0, "map parameters");

    edtmap::Mapper moved = std::move(mapper);
    CHECK(moved.distance({1.05, 0.05, 0.05}) > 0.99, "moved mapper");
    throws([&] { mapper.distance({1.05, 0.05, 0.05}); }, EDTMAP_NULL_ARGUMENT, "moved-from mapper", "mapper is null");

    throws([&] { edtmap::Map::load(std::string(argv[2]) + "/missing.edtmap"); }, EDTMAP_IO, "missing map");
    throws([&] { edtmap::Mapper::from_config(std::string(argv[2]) + "/missing.toml"); }, EDTMAP_IO, "missing config");
    throws([&] {
        edtmap::Params bad;
        bad.local_size_m[0] = -3.0;
        edtmap::Mapper m(bad);
    }, EDTMAP_CONFIG, "bad params");
    // Out-of-range enumerations and flags, as C++ can set them.
    throws([&] {
        edtmap::Params bad;
        bad.sensor = 42;
        edtmap::Mapper m(bad);
    }, EDTMAP_INVALID_ARGUMENT, "sensor 42", "edtmap_params.sensor = 42");
    throws([&] {
        edtmap::Params bad;
        bad.backend = 7;
        edtmap::Mapper m(bad);
    }, EDTMAP_INVALID_ARGUMENT, "backend 7", "edtmap_params.backend = 7");
    throws([&] {
        edtmap::Params bad;
        bad.exact = 0x7f;
        edtmap::Mapper m(bad);
    }, EDTMAP_INVALID_ARGUMENT, "exact 0x7f", "edtmap_params.exact = 127");
    // 3 is a value an edtmap_backend may hold (C++ gives it two bits) but
    // names no backend.
    throws([&] { edtmap::Mapper::from_config(std::string(argv[2]) + "/missing.toml", static_cast<edtmap_backend>(3)); },
           EDTMAP_INVALID_ARGUMENT, "backend 3", "backend = 3");
    throws([&] {
        edtmap::Pose pose = edtmap::identity_pose();
        pose[0] = NAN;
        moved.integrate_points(cloud, pose, 1.0);
    }, EDTMAP_INVALID_ARGUMENT, "NaN pose");
    throws([&] { moved.integrate_scan({1.0f, 2.0f}, 0.0, 0.1, edtmap::identity_pose(), 1.0); }, EDTMAP_FRAME, "scan to a point sensor");

    // Empty inputs: a batch of no points is an answer of size 0; an empty
    // frame reaches the mapper, which refuses it (EDTMAP_FRAME, not a null
    // argument), and the map is as it was.
    const std::vector<edtmap::Point> none;
    edtmap::QueryResult empty = moved.query(none, true);
    CHECK(empty.distances.empty() && empty.gradients.empty() && empty.states.empty(), "empty query");
    CHECK(moved.distances(none).empty() && map.distances(none).empty() && map.query(none).states.empty(), "empty distances");
    moved.query(nullptr, 0, nullptr);
    throws([&] { moved.integrate_points(std::vector<std::array<float, 3>>{}, edtmap::identity_pose(), 2.0); }, EDTMAP_FRAME, "empty cloud");
    throws([&] { moved.integrate_points(nullptr, 0, edtmap::identity_pose(), 2.0); }, EDTMAP_FRAME, "empty cloud by pointer");
    throws([&] { moved.integrate_range_image({}, edtmap::identity_pose(), 2.0); }, EDTMAP_FRAME, "empty range image");
    {
        edtmap::Params planar_params;
        planar_params.sensor = EDTMAP_SENSOR_PLANAR;
        edtmap::Mapper planar(planar_params);
        throws([&] { planar.integrate_scan({}, 0.0, 0.1, edtmap::identity_pose(), 2.0); }, EDTMAP_FRAME, "empty scan");
        CHECK(planar.query(none).distances.empty(), "empty query of an empty map");
    }
    CHECK(moved.distances(points) == rd, "the map changed after refused empty frames");
    // A second sensor's handle maps into the same map the first queries;
    // the map outlives the first handle.
    {
        edtmap::Mapper first(p);
        edtmap::Mapper second = first.add_sensor(p, "second");
        throws([&] { first.add_sensor(p, "second"); }, EDTMAP_CONFIG, "a second sensor of the same name");
        throws([&] { first.sensor("third"); }, EDTMAP_INVALID_ARGUMENT, "no sensor of that name");
        second.integrate_points(cloud, edtmap::identity_pose(), 0.0);
        CHECK(std::fabs(first.distance({0.55, 0.05, 0.05}) - 1.5) < 1e-9, "the first handle sees the second's frame");
        edtmap::Mapper again = first.sensor("points");
        first = std::move(again);
        CHECK(std::fabs(second.distance({0.55, 0.05, 0.05}) - 1.5) < 1e-9, "the map lives while a handle does");
    }

    book_example(argv[2]);
    std::printf("C++ API: all checks passed\n");
    return 0;
}
