// edtmap: a header-only C++17 wrapper over the C API (edtmap.h).
//
//   edtmap::Params p;                          // defaults, then set fields
//   p.voxel_size_m = 0.05;
//   edtmap::Mapper mapper(p);                  // or Mapper::from_config(path)
//   mapper.integrate_points(xyz, n, pose, stamp);
//   double d = mapper.distance({1.0, 2.0, 0.5}, &gradient);
//
// Errors are exceptions (edtmap::Error, a std::runtime_error carrying the
// edtmap_status): constructors cannot return a status, planners written
// against FIESTA or Voxblox already run under exception-safe code, and the
// hot path (a batched query into the caller's buffers) throws only on a
// caller's mistake. Handles are RAII (move-only). Buffers are taken as
// pointer and length, or as std::vector / std::array; with EDTMAP_EIGEN
// defined before including this header, Eigen types too. Empty buffers
// are fine (a null pointer with a length of 0): an empty batch of queries
// gives empty results, and an empty frame throws Error(EDTMAP_FRAME), as
// the mapper refuses a frame that observes nothing.
//
// Threads: as the C API says, every member may run concurrently with the
// others on one Mapper (frames are integrated one at a time; queries read
// the map as of the last finished frame and never wait); a Map is
// immutable. The header edtmap.h opens with the whole contract. Here the
// handles free themselves; a moved-from Mapper holds none, and a call on it
// throws Error(EDTMAP_NULL_ARGUMENT). Error keeps its own copy of the
// library's message.
#ifndef EDTMAP_HPP
#define EDTMAP_HPP

#include "edtmap.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#ifdef EDTMAP_EIGEN
#include <Eigen/Core>
#endif

namespace edtmap {

/// A failed call: the status and the library's message.
class Error : public std::runtime_error {
public:
    Error(edtmap_status status, const std::string& what) : std::runtime_error(what), status_(status) {}
    /// The C API's status code.
    edtmap_status status() const noexcept { return status_; }

private:
    edtmap_status status_;
};

namespace detail {
inline void check(edtmap_status s) {
    if (s != EDTMAP_OK) {
        throw Error(s, edtmap_last_error());
    }
}
}  // namespace detail

/// A pose T_world_sensor: a row-major 4 x 4 rigid transform.
using Pose = std::array<double, 16>;

/// The identity pose.
inline Pose identity_pose() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

/// A world point, metres.
using Point = std::array<double, 3>;

/// What one frame did.
using FrameStats = edtmap_frame_stats;

/// Explicit mapper parameters, filled with the library's defaults.
struct Params : edtmap_params {
    Params() : edtmap_params() { detail::check(edtmap_params_default(this)); }
};

/// Distances, gradients (3 per point) and states (EDTMAP_STATE_*) of a
/// batched query.
struct QueryResult {
    std::vector<double> distances;
    std::vector<double> gradients;
    std::vector<std::uint8_t> states;
};

/// A dense box of distances (metres, x fastest) and states.
struct DenseBox {
    edtmap_box info{};
    std::vector<float> distances;
    std::vector<std::uint8_t> states;
};

namespace detail {
// The queries both handle types share, over a C function with the
// signature of edtmap_map_query / edtmap_mapper_query.
template <class Handle, class QueryFn, class BoxFn>
class Queries {
public:
    /// Distances of n points (xyz: 3 n doubles) into distances (n), and
    /// gradients (3 n) and states (n) when not null.
    void query(const double* xyz, std::size_t n, double* distances, double* gradients = nullptr, std::uint8_t* states = nullptr,
               bool signed_distance = false) const {
        check(query_fn_(handle_(), xyz, n, signed_distance, distances, gradients, states));
    }

    /// Distances, gradients and states of `points`.
    QueryResult query(const std::vector<Point>& points, bool signed_distance = false) const {
        QueryResult r;
        r.distances.resize(points.size());
        r.gradients.resize(3 * points.size());
        r.states.resize(points.size());
        query(points.empty() ? nullptr : points.front().data(), points.size(), r.distances.data(), r.gradients.data(), r.states.data(), signed_distance);
        return r;
    }

    /// Distances of `points`.
    std::vector<double> distances(const std::vector<Point>& points, bool signed_distance = false) const {
        std::vector<double> d(points.size());
        query(points.empty() ? nullptr : points.front().data(), points.size(), d.data(), nullptr, nullptr, signed_distance);
        return d;
    }

    /// The distance at `p`, and its gradient into `gradient` when not null.
    double distance(const Point& p, Point* gradient = nullptr, bool signed_distance = false) const {
        double d = 0.0;
        query(p.data(), 1, &d, gradient ? gradient->data() : nullptr, nullptr, signed_distance);
        return d;
    }

    /// The state (EDTMAP_STATE_*) of the voxel holding `p`.
    std::uint8_t state(const Point& p) const {
        double d = 0.0;
        std::uint8_t s = 0;
        query(p.data(), 1, &d, nullptr, &s, false);
        return s;
    }

    /// The dense box [min_m, max_m) (world metres).
    DenseBox export_box(const Point& min_m, const Point& max_m, bool signed_distance = false) const {
        DenseBox b;
        check(box_fn_(handle_(), min_m.data(), max_m.data(), signed_distance, nullptr, nullptr, 0, &b.info));
        const std::size_t n = static_cast<std::size_t>(b.info.dims[0] * b.info.dims[1] * b.info.dims[2]);
        b.distances.resize(n);
        b.states.resize(n);
        check(box_fn_(handle_(), min_m.data(), max_m.data(), signed_distance, b.distances.data(), b.states.data(), n, &b.info));
        return b;
    }

#ifdef EDTMAP_EIGEN
    /// The distance at `p`, and its gradient into `gradient` when not null.
    double distance(const Eigen::Vector3d& p, Eigen::Vector3d* gradient = nullptr, bool signed_distance = false) const {
        double d = 0.0;
        query(p.data(), 1, &d, gradient ? gradient->data() : nullptr, nullptr, signed_distance);
        return d;
    }

    /// Distances of the columns of `points` into `distances`, gradients
    /// into `gradients` when not null.
    void query(const Eigen::Matrix<double, 3, Eigen::Dynamic>& points, Eigen::VectorXd& distances,
               Eigen::Matrix<double, 3, Eigen::Dynamic>* gradients = nullptr, bool signed_distance = false) const {
        const auto n = static_cast<std::size_t>(points.cols());
        distances.resize(points.cols());
        if (gradients) {
            gradients->resize(3, points.cols());
        }
        query(points.data(), n, distances.data(), gradients ? gradients->data() : nullptr, nullptr, signed_distance);
    }
#endif

protected:
    Queries(QueryFn q, BoxFn b) : query_fn_(q), box_fn_(b) {}
    virtual ~Queries() = default;
    Queries(const Queries&) = default;
    Queries& operator=(const Queries&) = default;
    virtual const Handle* handle_() const = 0;

private:
    QueryFn query_fn_;
    BoxFn box_fn_;
};

using MapQuery = edtmap_status (*)(const edtmap_map*, const double*, std::size_t, bool, double*, double*, std::uint8_t*);
using MapBox = edtmap_status (*)(const edtmap_map*, const double*, const double*, bool, float*, std::uint8_t*, std::size_t, edtmap_box*);
using MapperQuery = edtmap_status (*)(const edtmap_mapper*, const double*, std::size_t, bool, double*, double*, std::uint8_t*);
using MapperBox = edtmap_status (*)(const edtmap_mapper*, const double*, const double*, bool, float*, std::uint8_t*, std::size_t, edtmap_box*);
}  // namespace detail

/// A saved map, loaded for queries.
class Map : public detail::Queries<edtmap_map, detail::MapQuery, detail::MapBox> {
public:
    /// Loads the map saved at `path`.
    static Map load(const std::string& path) {
        edtmap_map* m = nullptr;
        detail::check(edtmap_map_load(path.c_str(), &m));
        return Map(m);
    }

    /// Voxel edge, metres.
    double voxel_size() const { return edtmap_map_voxel_size(h_.get()); }
    /// Cutoff of the distances, metres.
    double max_distance() const { return edtmap_map_max_distance(h_.get()); }
    /// The C handle.
    const edtmap_map* get() const noexcept { return h_.get(); }

private:
    explicit Map(edtmap_map* m) : Queries(&edtmap_map_query, &edtmap_map_export_box), h_(m, &edtmap_map_free) {}
    const edtmap_map* handle_() const override { return h_.get(); }
    std::shared_ptr<edtmap_map> h_;
};

/// A mapping pipeline: frames in, distances out.
class Mapper : public detail::Queries<edtmap_mapper, detail::MapperQuery, detail::MapperBox> {
public:
    /// A mapper with explicit parameters.
    explicit Mapper(const Params& params) : Queries(&edtmap_mapper_query, &edtmap_mapper_export_box), h_(nullptr, &edtmap_mapper_free) {
        edtmap_mapper* m = nullptr;
        detail::check(edtmap_mapper_new(&params, &m));
        h_.reset(m);
    }

    /// A mapper from a configuration file (the TOML of `edtmap run --config`).
    static Mapper from_config(const std::string& config_path, edtmap_backend backend = EDTMAP_BACKEND_CPU) {
        edtmap_mapper* m = nullptr;
        detail::check(edtmap_mapper_from_config(config_path.c_str(), backend, &m));
        return Mapper(m);
    }

    /// A mapper from a configuration file, continuing a saved map.
    static Mapper resume(const std::string& config_path, const std::string& map_path, edtmap_backend backend = EDTMAP_BACKEND_CPU) {
        edtmap_mapper* m = nullptr;
        detail::check(edtmap_mapper_resume(config_path.c_str(), map_path.c_str(), backend, &m));
        return Mapper(m);
    }

    Mapper(Mapper&&) noexcept = default;
    Mapper& operator=(Mapper&&) noexcept = default;

    /// Adds a sensor (`params`' sensor fields) named `name` to this map;
    /// the handle returned integrates its frames into the same map and
    /// queries the same map. The map lives while any handle does.
    Mapper add_sensor(const Params& params, const std::string& name) {
        edtmap_mapper* m = nullptr;
        detail::check(edtmap_mapper_add_sensor(h_.get(), &params, name.c_str(), &m));
        return Mapper(m);
    }

    /// A handle of this map's sensor `name` (a config's [[sensors]] entry,
    /// or one add_sensor added).
    Mapper sensor(const std::string& name) {
        edtmap_mapper* m = nullptr;
        detail::check(edtmap_mapper_sensor(h_.get(), name.c_str(), &m));
        return Mapper(m);
    }

    /// A point cloud: n points, xyz holding 3 n floats (sensor frame).
    FrameStats integrate_points(const float* xyz, std::size_t n, const Pose& t_world_sensor, double stamp_s) {
        FrameStats s{};
        detail::check(edtmap_integrate_points(h_.get(), xyz, n, t_world_sensor.data(), stamp_s, &s));
        return s;
    }

    /// A point cloud (sensor frame).
    FrameStats integrate_points(const std::vector<std::array<float, 3>>& points, const Pose& t_world_sensor, double stamp_s) {
        return integrate_points(points.empty() ? nullptr : points.front().data(), points.size(), t_world_sensor, stamp_s);
    }

    /// A depth image in metres, row by row.
    FrameStats integrate_depth(const float* depth_m, std::uint32_t width, std::uint32_t height, const Pose& t_world_sensor, double stamp_s) {
        FrameStats s{};
        detail::check(edtmap_integrate_depth(h_.get(), depth_m, width, height, t_world_sensor.data(), stamp_s, &s));
        return s;
    }

    /// A 16-bit depth image, each value times metres_per_unit metres.
    FrameStats integrate_depth(const std::uint16_t* depth, std::uint32_t width, std::uint32_t height, float metres_per_unit,
                               const Pose& t_world_sensor, double stamp_s) {
        FrameStats s{};
        detail::check(edtmap_integrate_depth_u16(h_.get(), depth, width, height, metres_per_unit, t_world_sensor.data(), stamp_s, &s));
        return s;
    }

    /// A planar scan: beam i at angle_min_rad + i angle_increment_rad.
    FrameStats integrate_scan(const std::vector<float>& ranges, double angle_min_rad, double angle_increment_rad, const Pose& t_world_sensor,
                              double stamp_s) {
        FrameStats s{};
        detail::check(edtmap_integrate_scan(h_.get(), ranges.data(), ranges.size(), angle_min_rad, angle_increment_rad, t_world_sensor.data(),
                                            stamp_s, &s));
        return s;
    }

    /// A spinning LiDAR's range image (rings x azimuth bins, ring by ring).
    FrameStats integrate_range_image(const std::vector<float>& ranges, const Pose& t_world_sensor, double stamp_s) {
        FrameStats s{};
        detail::check(edtmap_integrate_range_image(h_.get(), ranges.data(), ranges.size(), t_world_sensor.data(), stamp_s, &s));
        return s;
    }

#ifdef EDTMAP_EIGEN
    /// A point cloud (columns, sensor frame) seen from an Eigen pose.
    FrameStats integrate_points(const Eigen::Matrix<float, 3, Eigen::Dynamic>& points, const Eigen::Matrix4d& t_world_sensor, double stamp_s) {
        return integrate_points(points.data(), static_cast<std::size_t>(points.cols()), pose(t_world_sensor), stamp_s);
    }

    /// A row-major pose from an Eigen matrix (column-major by default).
    static Pose pose(const Eigen::Matrix4d& m) {
        Pose p{};
        for (int r = 0; r < 4; ++r) {
            for (int c = 0; c < 4; ++c) {
                p[static_cast<std::size_t>(4 * r + c)] = m(r, c);
            }
        }
        return p;
    }
#endif

    /// Saves the map (as of the last finished frame) atomically.
    void save(const std::string& path) const { detail::check(edtmap_mapper_save(h_.get(), path.c_str())); }

    /// The C handle.
    edtmap_mapper* get() const noexcept { return h_.get(); }

private:
    explicit Mapper(edtmap_mapper* m) : Queries(&edtmap_mapper_query, &edtmap_mapper_export_box), h_(m, &edtmap_mapper_free) {}
    const edtmap_mapper* handle_() const override { return h_.get(); }
    std::unique_ptr<edtmap_mapper, void (*)(edtmap_mapper*)> h_;
};

}  // namespace edtmap

#endif  // EDTMAP_HPP
