// A tool pose in part coordinates: what the fitting produces, the checks test and the
// kinematics turns into joints.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace flankcam {

struct ToolPose {
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();    // tool tip (end a of the axis), mm, part frame
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit, tip -> spindle, part frame
};

// The pose a fraction f of the way from p to q: the tip on the straight line, the axis turned along
// the great circle (slerp), as a controller with TCP interpolates a block.
inline ToolPose interpolate(const ToolPose& p, const ToolPose& q, double f) {
  const Eigen::Quaterniond turn = Eigen::Quaterniond::FromTwoVectors(p.axis, q.axis);
  return {(1 - f) * p.tip + f * q.tip, (Eigen::Quaterniond::Identity().slerp(f, turn) * p.axis).normalized()};
}

}  // namespace flankcam
