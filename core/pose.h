// A tool pose in part coordinates: what the fitting produces, the checks test and the
// kinematics turns into joints.
#pragma once
#include <Eigen/Core>

namespace flankcam {

struct ToolPose {
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();    // tool tip (end a of the axis), mm, part frame
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit, tip -> spindle, part frame
};

}  // namespace flankcam
