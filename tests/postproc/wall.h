// A wall x = r(z), y in [-half_width, half_width], z in [0, 20] mm: the envelope of a tool with
// meridian r standing at x = 0 with a vertical axis, tip at z = 0, moving along y.
#pragma once
#include <functional>

#include "core/mesh.h"

namespace flankcam::test {
inline TriMesh flank_wall(const std::function<double(double)>& r, double half_width, int ny, int nz) {
  TriMesh m;
  for (int j = 0; j <= nz; ++j)
    for (int i = 0; i <= ny; ++i) {
      const double z = 20.0 * j / nz, y = -half_width + 2 * half_width * i / ny;
      m.vertices.emplace_back(r(z), y, z);
    }
  for (int j = 0; j < nz; ++j)
    for (int i = 0; i < ny; ++i) {
      const int a = j * (ny + 1) + i, b = a + 1, c = a + ny + 1, d = c + 1;
      m.faces.push_back({a, b, d});
      m.faces.push_back({a, d, c});
    }
  return m;
}
}  // namespace flankcam::test
