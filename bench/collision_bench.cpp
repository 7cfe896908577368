// Collision check of 1,000 poses against a 200,000-triangle part (issue 6 goal: <= 0.2 s on 2 cores).
#include <fmt/format.h>

#include <Eigen/Geometry>
#include <chrono>

#include "core/collision.h"

using namespace flankcam;

int main() {
  // A wavy 300 x 300 mm part, 317 x 317 vertices (199,712 triangles).
  const int n = 317;
  const auto height = [](double x, double y) { return 10 * std::sin(0.11 * x) * std::cos(0.07 * y + 0.3 * std::sin(0.05 * x)); };
  TriMesh part;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = 300.0 * i / (n - 1), y = 300.0 * j / (n - 1);
      part.vertices.emplace_back(x, y, height(x, y));
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int v = j * n + i;
      part.faces.push_back({v, v + 1, v + n + 1});
      part.faces.push_back({v, v + n + 1, v + n});
    }
  const auto t0 = std::chrono::steady_clock::now();
  const SurfaceIndex index(part);
  const auto t1 = std::chrono::steady_clock::now();
  ToolAssembly tool;
  for (int j = 0; j <= 20; ++j) tool.cutter.emplace_back(2.0 * j, 5.0 + 0.1 * j);
  tool.shank_length = 30, tool.shank_diameter = 12;
  tool.holder_length = 40, tool.holder_diameter = 30, tool.holder_diameter_far = 50;
  // 1,000 poses along x, the cutter tip sphere 0.05 mm above the part, axis tilted 30 degrees.
  std::vector<ToolPose> poses;
  const Eigen::Vector3d axis = Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitY()) * Eigen::Vector3d::UnitZ();
  for (int i = 0; i < 1000; ++i) {
    const double x = 20 + 260.0 * i / 999, y = 150;
    poses.push_back({Eigen::Vector3d(x, y, height(x, y) + 5.05), axis});
  }
  CollisionOptions o;
  o.clearance_mm = 1;
  o.gouge_tolerance_mm = 0.01;
  const auto t2 = std::chrono::steady_clock::now();
  const CollisionReport r = check_collisions(index, poses, tool, o);
  const auto t3 = std::chrono::steady_clock::now();
  fmt::print("collision: {} triangles (index {:.2f} s), {} poses, {} positions, {} queries, {} intervals: {:.3f} s "
             "[goal <= 0.2 s]\n",
             part.faces.size(), std::chrono::duration<double>(t1 - t0).count(), poses.size(), r.positions_checked,
             r.queries, r.intervals.size(), std::chrono::duration<double>(t3 - t2).count());
}
