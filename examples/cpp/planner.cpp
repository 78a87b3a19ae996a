// Pushes a straight-line path out of collision along edtmap's distance
// gradient, the way a planner consumes an ESDF.
//
//   planner MAP [--height Z] [--margin M]
//
// Loads a map saved by edtmap (`edtmap demo` writes edtmap-out/map.edtmap),
// picks two free points at height Z (default 1.5 m) far apart along x with
// M (default 0.6 m) of clearance, and bends the straight line between them
// out of collision, CHOMP-style: the inner waypoints move up the signed
// distance's gradient wherever they are closer than M to an obstacle,
// against a smoothness cost, in the smoothness metric (ends fixed, kept in
// the horizontal plane). Prints the clearance before and after; exits 1 if
// the path still touches an obstacle.
#include <edtmap.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

using Path = std::vector<edtmap::Point>;

// Solves A x = r for CHOMP's smoothness metric A (2 on the diagonal, -1
// beside it), by the Thomas algorithm.
static std::vector<double> solve_smoothness(const std::vector<double>& r) {
    const std::size_t n = r.size();
    std::vector<double> c(n), x(n);
    double b = 2.0;
    x[0] = r[0] / b;
    for (std::size_t i = 1; i < n; ++i) {
        c[i] = -1.0 / b;
        b = 2.0 + c[i];
        x[i] = (r[i] + x[i - 1]) / b;
    }
    for (std::size_t i = n - 1; i > 0; --i) {
        x[i - 1] -= c[i] * x[i];
    }
    return x;
}

// The least signed distance along the polyline, sampled every `step`.
static double clearance(const edtmap::Map& map, const Path& path, double step) {
    std::vector<edtmap::Point> samples{path.front()};
    for (std::size_t i = 0; i + 1 < path.size(); ++i) {
        const auto& a = path[i];
        const auto& b = path[i + 1];
        double len = std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
        int n = std::max(1, static_cast<int>(std::ceil(len / step)));
        for (int k = 1; k <= n; ++k) {
            double t = static_cast<double>(k) / n;
            samples.push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])});
        }
    }
    auto d = map.distances(samples, true);
    return *std::min_element(d.begin(), d.end());
}

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: planner MAP [--height Z] [--margin M]\n");
        return 2;
    }
    double height = 1.5, margin = 0.6;
    for (int i = 2; i + 1 < argc; i += 2) {
        if (std::strcmp(argv[i], "--height") == 0) {
            height = std::atof(argv[i + 1]);
        } else if (std::strcmp(argv[i], "--margin") == 0) {
            margin = std::atof(argv[i + 1]);
        }
    }
    try {
        edtmap::Map map = edtmap::Map::load(argv[1]);
        const double vs = map.voxel_size();

        // Two free voxels with `margin` clearance at `height`, farthest apart along x.
        edtmap::DenseBox slice = map.export_box({-200.0, -200.0, height}, {200.0, 200.0, height + vs / 2});
        const auto nx = slice.info.dims[0], ny = slice.info.dims[1];
        long best_lo = -1, best_hi = -1;
        for (std::size_t k = 0; k < slice.distances.size(); ++k) {
            if (slice.states[k] == EDTMAP_STATE_FREE && slice.distances[k] >= margin) {
                if (best_lo < 0 || k % nx < static_cast<std::size_t>(best_lo) % nx) best_lo = static_cast<long>(k);
                if (best_hi < 0 || k % nx > static_cast<std::size_t>(best_hi) % nx) best_hi = static_cast<long>(k);
            }
        }
        if (best_lo < 0 || best_lo == best_hi) {
            std::fprintf(stderr, "no two free voxels with %.2f m clearance at z = %.2f m\n", margin, height);
            return 1;
        }
        auto centre = [&](long k) {
            const auto x = static_cast<std::size_t>(k) % nx, y = static_cast<std::size_t>(k) / nx % ny;
            return edtmap::Point{(static_cast<double>(slice.info.origin[0]) + static_cast<double>(x) + 0.5) * vs,
                                 (static_cast<double>(slice.info.origin[1]) + static_cast<double>(y) + 0.5) * vs, height};
        };
        const edtmap::Point start = centre(best_lo), goal = centre(best_hi);

        const int waypoints = 150;
        Path path(waypoints + 2);
        for (int i = 0; i <= waypoints + 1; ++i) {
            double t = static_cast<double>(i) / (waypoints + 1);
            path[i] = {start[0] + t * (goal[0] - start[0]), start[1] + t * (goal[1] - start[1]), height};
        }
        const double before = clearance(map, path, vs / 2);

        // CHOMP (Ratliff et al., 2009): gradient descent on an obstacle cost
        // of the signed distance plus a smoothness cost, the step taken in
        // the smoothness metric A = K^T K (K: finite differences), so a push
        // on one waypoint moves its neighbours along.
        const double step = 0.01, smoothness = 0.2;
        std::vector<edtmap::Point> inner(waypoints), grad(waypoints);
        std::vector<double> d(waypoints), g(3 * waypoints);
        for (int iter = 0; iter < 300; ++iter) {
            std::copy(path.begin() + 1, path.end() - 1, inner.begin());
            map.query(inner.front().data(), inner.size(), d.data(), g.data(), nullptr, true);
            for (int i = 0; i < waypoints; ++i) {
                // The obstacle cost's slope: -1 inside, (d - eps) / eps near.
                const double slope = d[i] < 0.0 ? -1.0 : (d[i] <= margin ? (d[i] - margin) / margin : 0.0);
                for (int a = 0; a < 2; ++a) {  // in the horizontal plane
                    const double smooth = 2.0 * inner[i][a] - path[i][a] - path[i + 2][a];
                    grad[i][a] = slope * g[3 * i + a] + smoothness * smooth;
                }
            }
            for (int a = 0; a < 2; ++a) {
                std::vector<double> rhs(waypoints);
                for (int i = 0; i < waypoints; ++i) rhs[i] = grad[i][a];
                const std::vector<double> x = solve_smoothness(rhs);
                for (int i = 0; i < waypoints; ++i) path[i + 1][a] -= step * x[i];
            }
        }
        const double after = clearance(map, path, vs / 2);
        double length = 0.0;
        for (std::size_t i = 0; i + 1 < path.size(); ++i) {
            length += std::hypot(path[i + 1][0] - path[i][0], path[i + 1][1] - path[i][1]);
        }
        std::printf("start [%.2f, %.2f, %.2f] goal [%.2f, %.2f, %.2f]\n", start[0], start[1], start[2], goal[0], goal[1], goal[2]);
        std::printf("straight line: %.2f m, clearance %.3f m\n", std::hypot(goal[0] - start[0], goal[1] - start[1]), before);
        std::printf("planned path:  %.2f m, clearance %.3f m\n", length, after);
        if (!(after > 0.0)) {
            std::fprintf(stderr, "the path still touches an obstacle: raise --margin\n");
            return 1;
        }
        return 0;
    } catch (const edtmap::Error& e) {
        std::fprintf(stderr, "planner: %s\n", e.what());
        return 1;
    }
}
