// Helpers shared by the test suites: scratch directories and small meshes.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sys/wait.h>
#include <random>
#include <string>
#include <unistd.h>

#include "core/envelope.h"
#include "core/fitting.h"
#include "core/mesh.h"

namespace flankcam::test {

// A fresh directory under the system temp dir, removed when the object dies.
struct ScratchDir {
  std::filesystem::path path;
  explicit ScratchDir(const std::string& tag) {
    static int counter = 0;
    path = std::filesystem::temp_directory_path() /
           ("flankcam-test-" + tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  [[nodiscard]] std::string file(const std::string& name) const { return (path / name).string(); }
};

inline void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

inline std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

#ifdef FLANKCAM_BINARY
// Runs the flankcam program with `args`; returns its exit code and what it wrote to stderr.
struct RunResult {
  int code = -1;
  std::string err;
};
inline RunResult run_flankcam(const std::string& args, const ScratchDir& dir) {
  const std::string err = dir.file("stderr.txt");
  const std::string cmd = std::string(FLANKCAM_BINARY) + " " + args + " > /dev/null 2> " + err;
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read_text(err)};
}
#endif

// A grid of nx x ny points point(i, j) (i fastest), each cell split into two triangles.
template <class Point>
TriMesh grid_mesh(int nx, int ny, Point point) {
  TriMesh m;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) m.vertices.push_back(point(i, j));
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int v = j * nx + i;
      m.faces.push_back({v, v + 1, v + nx + 1});
      m.faces.push_back({v, v + nx + 1, v + nx});
    }
  return m;
}

// A wavy height field z = f(x, y) on an nx x ny grid over [0, sx] x [0, sy] (mm).
inline TriMesh wavy_grid(int nx, int ny, double sx, double sy, double amplitude) {
  return grid_mesh(nx, ny, [&](int i, int j) {
    const double x = sx * i / (nx - 1), y = sy * j / (ny - 1);
    return Eigen::Vector3d(x, y, amplitude * std::sin(0.11 * x) * std::cos(0.07 * y + 0.3 * std::sin(0.05 * x)));
  });
}

// Both meshes as one (b's faces renumbered after a's vertices).
inline TriMesh merged(TriMesh a, const TriMesh& b) {
  const int base = int(a.vertices.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (const auto& f : b.faces) a.faces.push_back({f[0] + base, f[1] + base, f[2] + base});
  return a;
}

// A closed box, faces outward; each side split into n x n squares.
inline TriMesh box_mesh(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int n = 1) {
  TriMesh m;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const int base = int(m.vertices.size());
      for (int b = 0; b <= n; ++b)
        for (int a = 0; a <= n; ++a) {
          Eigen::Vector3d p;
          p[axis] = side ? hi[axis] : lo[axis];
          p[u] = lo[u] + (hi[u] - lo[u]) * a / n;
          p[v] = lo[v] + (hi[v] - lo[v]) * b / n;
          m.vertices.push_back(p);
        }
      for (int b = 0; b < n; ++b)
        for (int a = 0; a < n; ++a) {
          const int c = base + b * (n + 1) + a;
          // (u, v, axis) is right-handed: counter-clockwise in (u, v) faces +axis.
          if (side)
            m.faces.push_back({c, c + 1, c + n + 2}), m.faces.push_back({c, c + n + 2, c + n + 1});
          else
            m.faces.push_back({c, c + n + 2, c + 1}), m.faces.push_back({c, c + n + 1, c + n + 2});
        }
    }
  // One vertex per corner point: the sides share their edges (a closed mesh).
  TriMesh out;
  std::vector<int> index;
  for (const Eigen::Vector3d& p : m.vertices) {
    int found = -1;
    for (size_t k = 0; k < out.vertices.size() && found < 0; ++k)
      if ((out.vertices[k] - p).norm() < 1e-9) found = int(k);
    if (found < 0) found = int(out.vertices.size()), out.vertices.push_back(p);
    index.push_back(found);
  }
  for (auto f : m.faces) out.faces.push_back({index[size_t(f[0])], index[size_t(f[1])], index[size_t(f[2])]});
  return out;
}

// The flank x = 0.01 (y - 30)^2 + 0.15 z (y 0..60, z 0..20 mm, leaning back 8.5 degrees; a cylinder or
// cone moving along it envelopes it), 41 x 21 vertices, and the floor z <= 0 it stands on (mm).
inline TriMesh leaning_flank() {
  return grid_mesh(41, 21, [](int j, int k) {
    const double y = 1.5 * j, z = 1.0 * k;
    return Eigen::Vector3d(0.01 * (y - 30) * (y - 30) + 0.15 * z, y, z);
  });
}
inline TriMesh floor_under_leaning_flank() { return box_mesh({-30, -20, -20}, {60, 80, 0}, 4); }

// The plane x = 0.25 z (y 0..60, z 0..30 mm), 41 x 61 vertices: on its +x side it meets the floor
// z <= 0 (floor_under_leaning_flank) at 76 degrees, a flank leaning over its hub.
inline TriMesh steep_flank() {
  return grid_mesh(41, 61, [](int j, int k) { return Eigen::Vector3d(0.125 * k, 1.5 * j, 0.5 * k); });
}

// The height (z) of a flat end's lowest rim point: the tip face centred at `tip`, square to the unit
// `axis`, of radius `radius`.
inline double lowest_rim_z(const Eigen::Vector3d& tip, const Eigen::Vector3d& axis, double radius) {
  return tip.z() - radius * std::sqrt(std::max(0.0, 1 - axis.z() * axis.z()));
}

// The catalogue's circle-segment barrel barrel-d16-r150-l40 (Ø16 at the middle, profile radius
// 150 mm, 40 mm long) as sphere radii in mm, from its meridian.
inline ToolRadius catalogue_barrel_mm() {
  std::vector<Eigen::Vector2d> zr;
  for (int k = 0; k <= 80; ++k) {
    const double z = 40.0 * k / 80;
    zr.emplace_back(z, 8 - (150 - std::sqrt(150 * 150 - (z - 20) * (z - 20))));
  }
  return tool_from_meridian(zr, 12);
}

// An exact envelope of an analytic motion, scaled to a unit diagonal (the fitting's frame).
struct ExactEnvelope {
  LineMotion motion;
  Similarity frame;   // mm -> unit frame
  TriMesh unit_mesh;  // the envelope in the unit frame
};
inline ExactEnvelope exact_envelope(const char* kind, const RadiusProfile& profile, int n_s = 66, int n_t = 200) {
  AnalyticMotionOptions o;
  o.kind = kind;
  const LineMotion m = analytic_motion(o);
  const EnvelopeGrid g = envelope_grid(m, profile, n_s, n_t, 1);
  const Similarity s = unit_diagonal_frame(g.mesh);
  return {m, s, transformed(g.mesh, s)};
}

}  // namespace flankcam::test
