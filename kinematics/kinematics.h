// Forward and inverse kinematics of a Machine (one solver for every chain).
//
// Frames: the part (work) frame is the machine frame at zero rotary angles. A pose is the tool tip
// and the unit tool axis (tip -> spindle) in part coordinates. The linear joints X, Y, Z are the
// controlled point: the tool tip at zero head angles with tool-length compensation, i.e. the head's
// pivot point less (gauge length + tool length) along the spindle direction. Rotary joints are in
// degrees, in the Machine's rotary order.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "core/pose.h"
#include "kinematics/machine.h"

namespace flankcam {

struct Joints {
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();  // X, Y, Z, mm
  std::array<double, 2> rotary{0, 0};                // degrees, Machine::rotary order
};

// Joints -> pose. `tool_length_mm`: spindle nose to tip (matters for head axes only).
[[nodiscard]] ToolPose forward(const Machine& m, const Joints& q, double tool_length_mm);

// The rotary angles that point the tool along `axis_part`: the two-rotation problem
// R(ω1, α) R(ω2, β) v = w, both branches. `free[k]`: the pose is singular for angle k (the tool axis
// is along the primary rotary axis), any value of it works; it is returned as 0.
struct RotarySolution {
  std::array<double, 2> deg{0, 0};  // in (-180, 180]
  std::array<bool, 2> free{false, false};
};
[[nodiscard]] std::vector<RotarySolution> rotary_solutions(const Machine& m, const Eigen::Vector3d& axis_part);
// The same solutions without a heap allocation (the path solver's per-pose loop).
struct RotarySolutionPair {
  std::array<RotarySolution, 2> items{};
  int count = 0;
  [[nodiscard]] const RotarySolution* begin() const { return items.data(); }
  [[nodiscard]] const RotarySolution* end() const { return items.data() + count; }
};
[[nodiscard]] RotarySolutionPair rotary_solution_pair(const Machine& m, const Eigen::Vector3d& axis_part);

// Angle (deg) between the pose and the nearest singular orientation, where one rotary angle is free
// (e.g. the tool axis along the C axis of an A/C table). Near it the free angle swings fast.
[[nodiscard]] double singularity_angle_deg(const Machine& m, const Eigen::Vector3d& axis_part);

// The linear joints for a pose once the rotary angles are chosen.
[[nodiscard]] Eigen::Vector3d linear_joints(const Machine& m, const ToolPose& pose, const std::array<double, 2>& rotary_deg,
                                            double tool_length_mm);
// The same given cos_deg[k] = std::cos(rotary_deg[k] * pi / 180) and sin_deg[k] likewise (bit for bit
// the same result; the path solver reuses the cosines and sines).
[[nodiscard]] Eigen::Vector3d linear_joints(const Machine& m, const ToolPose& pose, const std::array<double, 2>& cos_deg,
                                            const std::array<double, 2>& sin_deg, double tool_length_mm);

// Part (work) frame -> machine frame at these rotary angles: the table chain (identity for head
// axes). Heights in the machine frame are what a safe Z must clear.
struct TableTransform {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  [[nodiscard]] Eigen::Vector3d apply(const Eigen::Vector3d& x_part) const { return R * x_part + t; }
};
[[nodiscard]] TableTransform table_transform(const Machine& m, const std::array<double, 2>& rotary_deg);

// Forward kinematics prepared for many evaluations at one tool length (the path solver checks
// every block at a few points): each rotary axis as its unit direction and a point on it, turned
// by Rodrigues' formula from the angle's cosine and sine, so that callers stepping through a block
// supply them without trigonometry. Equals forward() to rounding.
struct PreparedForward {
  std::array<Eigen::Vector3d, 2> direction, centre;  // per rotary axis; centre: pivot (heads: from the tip at zero angles)
  std::array<bool, 2> table{true, true};
  Eigen::Vector3d spindle = Eigen::Vector3d::UnitZ();
};
[[nodiscard]] PreparedForward prepare_forward(const Machine& m, double tool_length_mm);
// forward(m, {linear_mm, deg}, tool_length_mm) given cos_deg[k] = cos(deg[k]) and sin_deg[k] = sin(deg[k])
// (inline: the path solver calls it in its innermost loop).
[[nodiscard]] inline ToolPose forward(const PreparedForward& f, const Eigen::Vector3d& linear_mm,
                                      const std::array<double, 2>& cos_deg, const std::array<double, 2>& sin_deg) {
  // R(w, angle) v by Rodrigues' formula (w unit).
  const auto turned = [](const Eigen::Vector3d& w, double c, double s, const Eigen::Vector3d& v) -> Eigen::Vector3d {
    return c * v + s * w.cross(v) + ((1 - c) * w.dot(v)) * w;
  };
  // As forward(): the head chain (inner axis first) gives the tip's offset and the tool axis in the
  // machine frame; the table chain undone (outer axis first) brings both into the part frame.
  Eigen::Vector3d head = Eigen::Vector3d::Zero(), axis = f.spindle;
  for (int k = 1; k >= 0; --k) {
    const size_t a = size_t(k);
    if (f.table[a]) continue;
    head = f.centre[a] + turned(f.direction[a], cos_deg[a], sin_deg[a], head - f.centre[a]);
    axis = turned(f.direction[a], cos_deg[a], sin_deg[a], axis);
  }
  Eigen::Vector3d tip = linear_mm + head;
  for (size_t a = 0; a < 2; ++a) {
    if (!f.table[a]) continue;
    tip = f.centre[a] + turned(f.direction[a], cos_deg[a], -sin_deg[a], tip - f.centre[a]);
    axis = turned(f.direction[a], cos_deg[a], -sin_deg[a], axis);
  }
  return {tip, axis};
}

// The cosine of singularity_angle_deg (without the arc cosine: the path solver asks per pose).
[[nodiscard]] double singularity_cosine(const Machine& m, const Eigen::Vector3d& axis_part);

// Every joint solution of a pose (0, 1 or 2; limits not applied, free angles at 0).
[[nodiscard]] std::vector<Joints> inverse(const Machine& m, const ToolPose& pose, double tool_length_mm);

// The general two-rotation problem R(ω1, α) R(ω2, β) v = w for unit vectors (ω1 not parallel to ω2):
// 0, 1 or 2 solutions (α, β) in radians; free flags as in RotarySolution.
struct TwoRotations {
  double alpha = 0, beta = 0;
  bool alpha_free = false, beta_free = false;
};
[[nodiscard]] std::vector<TwoRotations> solve_two_rotations(const Eigen::Vector3d& w1, const Eigen::Vector3d& w2,
                                                            const Eigen::Vector3d& v, const Eigen::Vector3d& w);

}  // namespace flankcam
