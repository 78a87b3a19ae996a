// DynamicEDT3D side of bench/dynamicedt.sh: replays a sequence of occupancy
// changes exported by edtmap through Lau et al.'s incremental Euclidean
// distance transform (the Debian package libdynamicedt3d-dev, the CPU
// baseline of the GIE-mapping paper) and times each frame's update.
//
//   replay_dynamicedt CHANGES_FILE OUT_PREFIX [--repeat N]
//
// CHANGES_FILE (text; blank lines and lines starting with '#' are skipped):
//   edtmap-changes 1
//   voxel_size_m 0.2
//   max_distance_vox 10            (cutoff in voxels, integer or real)
//   box MIN_X MIN_Y MIN_Z NX NY NZ (world voxel index of the corner, size)
//   frames N
//   frame K set S clear C          (N such blocks)
//   X Y Z                          (S lines: box-local voxels that became obstacles)
//   X Y Z                          (C lines: voxels that stopped being obstacles)
//
// Each repeat starts from a fresh DynamicEDT3D on an empty NX x NY x NZ grid.
// Per frame it applies all clears, then all sets (a voxel in both ends up an
// obstacle), then calls update(true); only those edits and the update are
// timed (std::chrono::steady_clock). With --repeat N the whole sequence is
// replayed N times and each frame keeps its minimum time.
//
// Cutoff. DynamicEDT3D takes a maximum squared distance M in cells. A cell's
// squared distance is exact while below M; at M and beyond it is clamped to
// M (getDistance() answers sqrt(M)) and the cell is not propagated further.
// Squared cell distances are integers, so M = floor(D^2) + 1 for D =
// max_distance_vox makes every distance <= D exact and every distance > D
// read as M. The output writes +inf for those cells (and everywhere when
// there is no obstacle), which compares directly with an exact EDT
// truncated at D.
//
// Outputs:
//   OUT_PREFIX.times.csv  frame,set,clear,update_ms (set and clear as listed
//                         in the file; update_ms the minimum over repeats)
//   OUT_PREFIX.final.f32  the final distance field in voxels, NX*NY*NZ
//                         little-endian float32, x fastest, then y, then z
//   stdout: one JSON line {"tool":"dynamicedt","frames":...,"total_ms":...,
//                          "median_ms":...,...}
//
// Exit status: 0 on success, 2 for bad arguments or a malformed changes file
// (the message names the line), 1 for other failures (e.g. writing outputs).

#include <dynamicEDT3D/dynamicEDT3D.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace {

constexpr int kExitFailure = 1;
constexpr int kExitBadInput = 2;
constexpr int kFormatVersion = 1;

// A malformed changes file or bad arguments (exit status 2).
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Voxel {
  int x, y, z;
};

struct Frame {
  long long index;
  std::vector<Voxel> set, clear;
};

struct Changes {
  double voxel_size_m = 0;
  double max_distance_vox = 0;
  long long min[3] = {0, 0, 0};  // world voxel index of the box corner
  int n[3] = {0, 0, 0};          // box size in voxels
  std::vector<Frame> frames;
};

// Walks the file line by line, splitting each into whitespace tokens and
// skipping blank and '#' lines, so that every error can name its line.
class LineReader {
 public:
  LineReader(std::string path, std::string text) : path_(std::move(path)), text_(std::move(text)) {}

  bool next(std::vector<std::string_view>& tok) {
    while (pos_ < text_.size()) {
      std::size_t end = text_.find('\n', pos_);
      if (end == std::string::npos) end = text_.size();
      std::string_view line(text_.data() + pos_, end - pos_);
      pos_ = end + 1;
      ++line_;
      split(line, tok);
      if (!tok.empty() && tok[0][0] != '#') return true;
    }
    tok.clear();
    return false;
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(path_ + ":" + std::to_string(line_) + ": " + what);
  }

  [[noreturn]] void fail_eof(const std::string& expected) const {
    throw InputError(path_ + ":" + std::to_string(line_ + 1) + ": file ends early; expected " + expected);
  }

 private:
  static void split(std::string_view line, std::vector<std::string_view>& tok) {
    tok.clear();
    std::size_t i = 0;
    while (true) {
      while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
      if (i == line.size()) return;
      std::size_t j = i;
      while (j < line.size() && !std::isspace(static_cast<unsigned char>(line[j]))) ++j;
      tok.push_back(line.substr(i, j - i));
      i = j;
    }
  }

  std::string path_;
  std::string text_;
  std::size_t pos_ = 0;
  std::size_t line_ = 0;
};

template <typename T>
T parse(const LineReader& in, std::string_view s, const char* what) {
  T v{};
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size())
    in.fail(std::string("bad ") + what + " '" + std::string(s) + "'");
  return v;
}

// Reads the next line, which must be KEY followed by `values` tokens.
std::vector<std::string_view> expect(LineReader& in, const std::string& key, std::size_t values) {
  std::vector<std::string_view> tok;
  if (!in.next(tok)) in.fail_eof("'" + key + "' line");
  if (tok[0] != key || tok.size() != values + 1)
    in.fail("expected '" + key + "' and " + std::to_string(values) + " value(s)");
  return tok;
}

void read_header(LineReader& in, Changes& c) {
  std::vector<std::string_view> tok;
  if (!in.next(tok)) in.fail_eof("'edtmap-changes 1'");
  if (tok[0] != "edtmap-changes" || tok.size() != 2) in.fail("not an edtmap changes file (expected 'edtmap-changes 1')");
  if (parse<int>(in, tok[1], "version") != kFormatVersion)
    in.fail("unsupported version " + std::string(tok[1]) + " (this harness reads version 1)");

  c.voxel_size_m = parse<double>(in, expect(in, "voxel_size_m", 1)[1], "voxel_size_m");
  if (!(c.voxel_size_m > 0) || !std::isfinite(c.voxel_size_m)) in.fail("voxel_size_m must be > 0");

  c.max_distance_vox = parse<double>(in, expect(in, "max_distance_vox", 1)[1], "max_distance_vox");
  // M = floor(D^2) + 1 must fit an int.
  if (!(c.max_distance_vox > 0) || !(c.max_distance_vox < 46340)) in.fail("max_distance_vox must be in (0, 46340)");

  tok = expect(in, "box", 6);
  for (int a = 0; a < 3; ++a) {
    c.min[a] = parse<long long>(in, tok[1 + a], "box corner");
    c.n[a] = parse<int>(in, tok[4 + a], "box size");
    if (c.n[a] < 1) in.fail("box sizes must be >= 1");
  }

  long long frames = parse<long long>(in, expect(in, "frames", 1)[1], "frame count");
  if (frames < 0) in.fail("frame count must be >= 0");
  c.frames.resize(static_cast<std::size_t>(frames));
}

void read_voxels(LineReader& in, const Changes& c, long long count, const char* kind, std::vector<Voxel>& out) {
  std::vector<std::string_view> tok;
  out.reserve(static_cast<std::size_t>(std::min<long long>(count, 1 << 20)));
  for (long long i = 0; i < count; ++i) {
    if (!in.next(tok))
      in.fail_eof(std::to_string(count - i) + " more '" + kind + "' voxel line(s)");
    if (tok.size() != 3) in.fail(std::string("expected a '") + kind + "' voxel 'X Y Z'");
    int v[3];
    for (int a = 0; a < 3; ++a) {
      v[a] = parse<int>(in, tok[a], "voxel coordinate");
      if (v[a] < 0 || v[a] >= c.n[a])
        in.fail(std::string("voxel ") + "xyz"[a] + " = " + std::to_string(v[a]) + " outside the box (0.." +
                std::to_string(c.n[a] - 1) + ")");
    }
    out.push_back({v[0], v[1], v[2]});
  }
}

Changes read_changes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open");
  std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  LineReader in(path, std::move(text));

  Changes c;
  read_header(in, c);
  std::vector<std::string_view> tok;
  for (std::size_t k = 0; k < c.frames.size(); ++k) {
    if (!in.next(tok)) in.fail_eof("frame " + std::to_string(k + 1) + " of " + std::to_string(c.frames.size()));
    if (tok.size() != 6 || tok[0] != "frame" || tok[2] != "set" || tok[4] != "clear")
      in.fail("expected 'frame K set S clear C'");
    Frame& fr = c.frames[k];
    fr.index = parse<long long>(in, tok[1], "frame number");
    const long long sets = parse<long long>(in, tok[3], "set count");
    const long long clears = parse<long long>(in, tok[5], "clear count");
    if (sets < 0 || clears < 0) in.fail("set and clear counts must be >= 0");
    read_voxels(in, c, sets, "set", fr.set);
    read_voxels(in, c, clears, "clear", fr.clear);
  }
  if (in.next(tok)) in.fail("content after the " + std::to_string(c.frames.size()) + " frame(s) announced by 'frames'");
  return c;
}

// Smallest M with every squared cell distance <= D^2 below it (see the top).
int max_squared_cells(double max_distance_vox) {
  return static_cast<int>(std::floor(max_distance_vox * max_distance_vox)) + 1;
}

// Replays every frame on `edt` (fresh, not yet initialised); returns each
// frame's edit + update time in milliseconds.
std::vector<double> replay(const Changes& c, DynamicEDT3D& edt) {
  edt.initializeEmpty(c.n[0], c.n[1], c.n[2]);
  std::vector<double> ms;
  ms.reserve(c.frames.size());
  for (const Frame& fr : c.frames) {
    const auto t0 = std::chrono::steady_clock::now();
    for (const Voxel& v : fr.clear) edt.clearCell(v.x, v.y, v.z);
    for (const Voxel& v : fr.set) edt.occupyCell(v.x, v.y, v.z);
    edt.update(true);
    const auto t1 = std::chrono::steady_clock::now();
    ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
  }
  return ms;
}

void write_times(const std::string& path, const Changes& c, const std::vector<double>& ms) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw std::runtime_error(path + ": cannot write");
  std::fprintf(f, "frame,set,clear,update_ms\n");
  for (std::size_t k = 0; k < ms.size(); ++k)
    std::fprintf(f, "%lld,%zu,%zu,%.6f\n", c.frames[k].index, c.frames[k].set.size(), c.frames[k].clear.size(),
                 ms[k]);
  if (std::fclose(f) != 0) throw std::runtime_error(path + ": write failed");
}

// Writes the field in voxels, +inf where the squared distance reached M;
// returns the number of obstacle cells.
std::size_t write_field(const std::string& path, const Changes& c, const DynamicEDT3D& edt, int max_sq) {
  const std::size_t nx = c.n[0], ny = c.n[1], nz = c.n[2];
  std::vector<unsigned char> bytes(nx * ny * nz * 4);
  std::size_t obstacles = 0;
  for (int x = 0; x < c.n[0]; ++x)
    for (int y = 0; y < c.n[1]; ++y)
      for (int z = 0; z < c.n[2]; ++z) {
        const float d = edt.getSQCellDistance(x, y, z) >= max_sq ? std::numeric_limits<float>::infinity()
                                                                 : edt.getDistance(x, y, z);
        if (edt.isOccupied(x, y, z)) ++obstacles;
        std::uint32_t u;
        std::memcpy(&u, &d, 4);
        unsigned char* p = &bytes[4 * (x + nx * (y + ny * z))];
        for (int b = 0; b < 4; ++b) p[b] = static_cast<unsigned char>(u >> (8 * b));
      }
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!f) throw std::runtime_error(path + ": write failed");
  return obstacles;
}

std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') out += '\\';
    out += ch;
  }
  return out + "\"";
}

int run(int argc, char** argv) {
  if (argc != 3 && !(argc == 5 && std::string(argv[3]) == "--repeat"))
    throw InputError(std::string("usage: ") + argv[0] + " CHANGES_FILE OUT_PREFIX [--repeat N]");
  const std::string changes_path = argv[1], prefix = argv[2];
  int repeats = 1;
  if (argc == 5) {
    const std::string_view s = argv[4];
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), repeats);
    if (ec != std::errc() || end != s.data() + s.size() || repeats < 1)
      throw InputError("--repeat needs an integer >= 1, not '" + std::string(s) + "'");
  }

  const Changes c = read_changes(changes_path);
  const int max_sq = max_squared_cells(c.max_distance_vox);

  std::vector<double> best;
  std::unique_ptr<DynamicEDT3D> edt;
  for (int r = 0; r < repeats; ++r) {
    edt = std::make_unique<DynamicEDT3D>(max_sq);  // fresh map, untimed
    const std::vector<double> ms = replay(c, *edt);
    if (r == 0) best = ms;
    for (std::size_t k = 0; k < ms.size(); ++k) best[k] = std::min(best[k], ms[k]);
  }

  write_times(prefix + ".times.csv", c, best);
  const std::size_t obstacles = write_field(prefix + ".final.f32", c, *edt, max_sq);

  double total = 0;
  for (double t : best) total += t;
  std::vector<double> sorted = best;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t n = sorted.size();
  const double median = n == 0 ? 0 : n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  std::printf(
      "{\"tool\":\"dynamicedt\",\"changes\":%s,\"frames\":%zu,\"repeats\":%d,\"box\":[%d,%d,%d],"
      "\"voxel_size_m\":%g,\"max_distance_vox\":%g,\"max_sq_cells\":%d,\"total_ms\":%.3f,\"median_ms\":%.3f,"
      "\"max_ms\":%.3f,\"final_obstacles\":%zu}\n",
      json_string(changes_path).c_str(), n, repeats, c.n[0], c.n[1], c.n[2], c.voxel_size_m, c.max_distance_vox,
      max_sq, total, median, n == 0 ? 0 : sorted[n - 1], obstacles);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const InputError& e) {
    std::fprintf(stderr, "replay_dynamicedt: %s\n", e.what());
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "replay_dynamicedt: %s\n", e.what());
    return kExitFailure;
  }
}
