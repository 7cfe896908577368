// The small fixed patch the emitters' golden files and round trips use.
#pragma once
#include <Eigen/Geometry>
#include <cmath>

#include "postproc/apt.h"

namespace flankcam::test {

// 5 poses of a cone tool (r 6 -> 9 over 40 mm) sweeping an arc with a twist.
inline ClProgram small_patch() {
  std::vector<ToolPose> poses;
  for (int i = 0; i < 5; ++i) {
    const double a = i * 0.1;
    const Eigen::Vector3d axis = Eigen::AngleAxisd(0.2 + 0.05 * i, Eigen::Vector3d(std::cos(a), std::sin(a), 0)) * Eigen::Vector3d::UnitZ();
    poses.push_back({Eigen::Vector3d(100 * std::cos(a), 100 * std::sin(a), -5.5 + i), axis});
  }
  std::vector<Eigen::Vector2d> profile;
  for (int k = 0; k <= 4; ++k) profile.emplace_back(10.0 * k, 6 + 0.75 * k);
  ClProgram p = flank_program("SMALL-PATCH", poses, profile, 800, 12000, 5, 50);
  p.comments = {"FLANKCAM TEST PATCH, EPS 0.0040 MM"};
  return p;
}

}  // namespace flankcam::test
