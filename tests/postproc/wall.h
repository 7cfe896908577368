// A wall x = r(z), y in [-half_width, half_width], z in [0, 20] mm: the envelope of a tool with
// meridian r standing at x = 0 with a vertical axis, tip at z = 0, moving along y.
#pragma once
#include <functional>

#include "core/mesh.h"
#include "tests/test_util.h"

namespace flankcam::test {
inline TriMesh flank_wall(const std::function<double(double)>& r, double half_width, int ny, int nz) {
  return grid_mesh(ny + 1, nz + 1, [&](int i, int j) {
    const double z = 20.0 * j / nz, y = -half_width + 2 * half_width * i / ny;
    return Eigen::Vector3d(r(z), y, z);
  });
}
}  // namespace flankcam::test
