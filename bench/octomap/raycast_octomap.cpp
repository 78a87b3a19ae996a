// OctoMap side of bench/raycast.sh: times octomap::OcTree::insertPointCloud
// on one PCD scan.
//
//   raycast_octomap PCD VOXEL_M MAX_RANGE_M REPEATS
//
// Reads the x, y, z fields (F4 or F8) of a PCD file with DATA ascii or
// binary (other fields of any type are skipped), drops "no return" points
// (non-finite, or exactly at the origin: the sensor writes (0, 0, 0) for
// them, and edtmap treats a zero range as no return too), and inserts the
// rest from the origin (0, 0, 0) with the given maximum range. Each repeat
// builds a fresh OcTree(VOXEL_M) with OctoMap's default sensor model (hit
// 0.7, miss 0.4, clamping 0.12 / 0.97) and times only
// insertPointCloud(cloud, origin, max_range) with its defaults
// (lazy_eval = false, discretize = false) using std::chrono::steady_clock.
//
// Built without -fopenmp (as the Debian library itself is) the ray casting
// runs on one thread. Built with -fopenmp, OctoMap's own OpenMP loop in
// computeUpdate (compiled from the headers into this program) runs on
// OMP_NUM_THREADS threads; the tree below sizes its per-thread ray buffers
// for that, which the library's constructor does not do.
//
// Prints one JSON line:
//   {"tool":"octomap","pcd":...,"voxel_size_m":...,"max_range_m":...,
//    "points":...,"points_in_file":...,"repeats":...,"threads":...,
//    "median_ms":...,"min_ms":...,"leaf_nodes":...,"occupied_leaves":...,
//    "occupied_voxels":...,"free_voxels":...}
// where points is the number inserted, leaf_nodes and occupied_leaves
// count the pruned tree's leaves after one insertion, and occupied_voxels /
// free_voxels count voxels of size VOXEL_M (a pruned leaf of depth d stands
// for 8^(16-d) of them).

#include <octomap/octomap.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace {

struct Cloud {
  std::vector<float> xyz;  // x y z of each point
  std::size_t in_file = 0;
};

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

std::vector<std::string> split(const std::string& line) {
  std::istringstream in(line);
  return {std::istream_iterator<std::string>(in), std::istream_iterator<std::string>()};
}

// A minimal PCD reader: enough for ascii and binary files with float x y z.
Cloud read_pcd(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) fail(path, "cannot open");
  std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::vector<std::string> fields, sizes, types, counts;
  std::size_t points = 0, width = 0, height = 1;
  bool have_points = false;
  std::string data;
  std::size_t pos = 0;
  while (data.empty()) {
    if (pos >= bytes.size()) fail(path, "no DATA line");
    std::size_t end = pos;
    while (end < bytes.size() && bytes[end] != '\n') ++end;
    std::vector<std::string> tok = split(std::string(bytes.data() + pos, end - pos));
    pos = end + 1;
    if (tok.empty() || tok[0][0] == '#') continue;
    std::vector<std::string> rest(tok.begin() + 1, tok.end());
    const std::string& key = tok[0];
    if (key == "FIELDS" || key == "COLUMNS") fields = rest;
    else if (key == "SIZE") sizes = rest;
    else if (key == "TYPE") types = rest;
    else if (key == "COUNT") counts = rest;
    else if (key == "WIDTH" && rest.size() == 1) width = std::stoull(rest[0]);
    else if (key == "HEIGHT" && rest.size() == 1) height = std::stoull(rest[0]);
    else if (key == "POINTS" && rest.size() == 1) { points = std::stoull(rest[0]); have_points = true; }
    else if (key == "DATA" && rest.size() == 1) data = rest[0];
  }
  if (!have_points) points = width * height;
  if (counts.empty()) counts.assign(fields.size(), "1");
  if (sizes.size() != fields.size() || types.size() != fields.size() || counts.size() != fields.size())
    fail(path, "FIELDS, SIZE, TYPE and COUNT differ in length");
  // Byte offset, ascii column and size of x, y, z.
  std::size_t offset[3], column[3], size[3];
  bool found[3] = {false, false, false};
  std::size_t point_size = 0, values = 0;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    std::size_t s = std::stoull(sizes[i]), c = std::stoull(counts[i]);
    for (int a = 0; a < 3; ++a) {
      if (fields[i] == std::string(1, "xyz"[a])) {
        if (types[i] != "F" || (s != 4 && s != 8) || c != 1) fail(path, "field " + fields[i] + " is not F4 or F8");
        offset[a] = point_size;
        column[a] = values;
        size[a] = s;
        found[a] = true;
      }
    }
    point_size += s * c;
    values += c;
  }
  for (int a = 0; a < 3; ++a)
    if (!found[a]) fail(path, std::string("no field ") + "xyz"[a]);

  Cloud cloud;
  cloud.in_file = points;
  cloud.xyz.reserve(points * 3);
  if (data == "binary") {
    if (bytes.size() < pos || bytes.size() - pos < points * point_size) fail(path, "truncated binary data");
    for (std::size_t p = 0; p < points; ++p) {
      const char* pt = bytes.data() + pos + p * point_size;
      for (int a = 0; a < 3; ++a) {
        if (size[a] == 4) {
          float v;
          std::memcpy(&v, pt + offset[a], 4);
          cloud.xyz.push_back(v);
        } else {
          double v;
          std::memcpy(&v, pt + offset[a], 8);
          cloud.xyz.push_back(static_cast<float>(v));
        }
      }
    }
  } else if (data == "ascii") {
    std::istringstream in(std::string(bytes.data() + std::min(pos, bytes.size()), bytes.data() + bytes.size()));
    std::string line;
    std::size_t p = 0;
    while (p < points && std::getline(in, line)) {
      std::vector<std::string> tok = split(line);
      if (tok.empty()) continue;
      if (tok.size() != values) fail(path, "ascii line with the wrong number of values");
      for (int a = 0; a < 3; ++a) cloud.xyz.push_back(std::strtof(tok[column[a]].c_str(), nullptr));
      ++p;
    }
    if (p < points) fail(path, "fewer ascii lines than POINTS");
  } else {
    fail(path, "DATA " + data + " is not supported");
  }
  return cloud;
}

// OcTree whose per-thread ray buffers match the OpenMP thread count.
class Tree : public octomap::OcTree {
 public:
  explicit Tree(double resolution) : octomap::OcTree(resolution) {
#ifdef _OPENMP
    keyrays.resize(std::max(1, omp_get_max_threads()));
#endif
  }
  int threads() const { return static_cast<int>(keyrays.size()); }
};

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: %s PCD VOXEL_M MAX_RANGE_M REPEATS\n", argv[0]);
    return 2;
  }
  try {
    const std::string pcd = argv[1];
    const double voxel = std::stod(argv[2]);
    const double max_range = std::stod(argv[3]);
    const int repeats = std::stoi(argv[4]);
    if (!(voxel > 0) || !(max_range > 0) || repeats < 1) throw std::runtime_error("need VOXEL_M > 0, MAX_RANGE_M > 0, REPEATS >= 1");

    const Cloud raw = read_pcd(pcd);
    octomap::Pointcloud cloud;
    cloud.reserve(raw.xyz.size() / 3);
    for (std::size_t i = 0; i + 2 < raw.xyz.size(); i += 3) {
      const float x = raw.xyz[i], y = raw.xyz[i + 1], z = raw.xyz[i + 2];
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) continue;
      if (x == 0.0f && y == 0.0f && z == 0.0f) continue;
      cloud.push_back(x, y, z);
    }
    const octomap::point3d origin(0.0f, 0.0f, 0.0f);

    std::vector<double> ms;
    std::size_t leaves = 0, occupied_leaves = 0;
    std::uint64_t occupied_voxels = 0, free_voxels = 0;
    int threads = 1;
    for (int r = 0; r < repeats; ++r) {
      Tree tree(voxel);  // defaults: hit 0.7, miss 0.4, clamping 0.12 / 0.97
      threads = tree.threads();
      const auto t0 = std::chrono::steady_clock::now();
      tree.insertPointCloud(cloud, origin, max_range);
      const auto t1 = std::chrono::steady_clock::now();
      ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      if (r == 0) {
        const unsigned depth = tree.getTreeDepth();
        for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
          ++leaves;
          const std::uint64_t n = std::uint64_t(1) << (3 * (depth - it.getDepth()));
          if (tree.isNodeOccupied(*it)) {
            ++occupied_leaves;
            occupied_voxels += n;
          } else {
            free_voxels += n;
          }
        }
      }
    }
    std::vector<double> sorted = ms;
    std::sort(sorted.begin(), sorted.end());
    const std::size_t n = sorted.size();
    const double median = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);

    std::string escaped;
    for (char c : pcd) {
      if (c == '"' || c == '\\') escaped += '\\';
      escaped += c;
    }
    std::printf(
        "{\"tool\":\"octomap\",\"pcd\":\"%s\",\"voxel_size_m\":%g,\"max_range_m\":%g,\"points\":%zu,"
        "\"points_in_file\":%zu,\"repeats\":%d,\"threads\":%d,\"median_ms\":%.3f,\"min_ms\":%.3f,"
        "\"leaf_nodes\":%zu,\"occupied_leaves\":%zu,\"occupied_voxels\":%llu,\"free_voxels\":%llu}\n",
        escaped.c_str(), voxel, max_range, cloud.size(), raw.in_file, repeats, threads, median, sorted[0],
        leaves, occupied_leaves, static_cast<unsigned long long>(occupied_voxels),
        static_cast<unsigned long long>(free_voxels));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "raycast_octomap: %s\n", e.what());
    return 1;
  }
  return 0;
}
