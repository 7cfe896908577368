#include "kinematics/kinematics.h"

#include <Eigen/Geometry>
#include <cmath>

namespace flankcam {

namespace {

constexpr double kDeg = M_PI / 180;
constexpr double kFree = 1e-9;  // |component normal to the axis| below this: the angle is free

// Eigen::AngleAxisd(angle, axis).toRotationMatrix() given c = cos(angle), s = sin(angle): the same
// operations in the same order, so the same bits (the path solver has the cosines and sines).
Eigen::Matrix3d rot(const Eigen::Vector3d& axis, double c, double s) {
  Eigen::Matrix3d res;
  const Eigen::Vector3d sin_axis = s * axis, cos1_axis = (1 - c) * axis;
  double tmp = cos1_axis.x() * axis.y();
  res(0, 1) = tmp - sin_axis.z();
  res(1, 0) = tmp + sin_axis.z();
  tmp = cos1_axis.x() * axis.z();
  res(0, 2) = tmp + sin_axis.y();
  res(2, 0) = tmp - sin_axis.y();
  tmp = cos1_axis.y() * axis.z();
  res(1, 2) = tmp - sin_axis.x();
  res(2, 1) = tmp + sin_axis.x();
  res.diagonal() = (cos1_axis.cwiseProduct(axis)).array() + c;
  return res;
}

// The affine map of the table chain (part -> machine) or the head chain (tool -> ram), outer axis
// first: x -> c0 + R0 (c1 + R1 (x - c1) - c0). Tables rotate about points in part coordinates;
// heads about points relative to the tip at zero angles.
struct Chain {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  [[nodiscard]] Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return R * x + t; }
  [[nodiscard]] Eigen::Vector3d apply_inverse(const Eigen::Vector3d& y) const { return R.transpose() * (y - t); }
};

struct Chains {
  Chain table, head;
};
// Both chains with one rotation matrix per axis. The inner (carried) axis is applied first, so
// that the outer axis acts on the result.
// `cos_deg`, `sin_deg`: the cosines and sines of the angles in degrees, as std::cos(deg * kDeg).
Chains chains(const Machine& m, const std::array<double, 2>& cos_deg, const std::array<double, 2>& sin_deg,
              double tool_length) {
  Chains c;
  for (int k = 1; k >= 0; --k) {
    const RotaryAxis& a = m.rotary[size_t(k)];
    const bool table = a.carries == Carrier::Table;
    const Eigen::Vector3d centre = table ? a.pivot : a.pivot + (m.gauge_length_mm + tool_length) * m.spindle_direction;
    const Eigen::Matrix3d R = rot(a.direction, cos_deg[size_t(k)], sin_deg[size_t(k)]);
    Chain& ch = table ? c.table : c.head;
    ch.R = R * ch.R;
    ch.t = R * (ch.t - centre) + centre;
  }
  return c;
}
Chains chains(const Machine& m, const std::array<double, 2>& deg, double tool_length) {
  std::array<double, 2> c{}, s{};
  for (size_t k = 0; k < 2; ++k) c[k] = std::cos(deg[k] * kDeg), s[k] = std::sin(deg[k] * kDeg);
  return chains(m, c, s, tool_length);
}

// Angle that turns p into q about the unit axis w (components along w ignored); nullopt-like flag
// when p or q is along w.
double angle_about(const Eigen::Vector3d& w, const Eigen::Vector3d& p, const Eigen::Vector3d& q, bool& free) {
  const Eigen::Vector3d pp = p - p.dot(w) * w, qq = q - q.dot(w) * w;
  free = pp.norm() < kFree || qq.norm() < kFree;
  if (free) return 0;
  return std::atan2(w.dot(pp.cross(qq)), pp.dot(qq));
}

double wrap180(double deg) {
  if (deg > -180 && deg <= 180) return deg + 0.0;  // what the remainder below gives, without it
  double x = std::remainder(deg, 360.0);
  if (x <= -180) x += 360;
  return x + 0.0;
}

}  // namespace

namespace {
struct TwoRotationsPair {
  std::array<TwoRotations, 2> items{};
  int count = 0;
};
// solve_two_rotations without allocating (the path solver calls it for every pose).
TwoRotationsPair two_rotations(const Eigen::Vector3d& w1, const Eigen::Vector3d& w2, const Eigen::Vector3d& v,
                               const Eigen::Vector3d& w) {
  // u = R(ω2, β) v = R(ω1, -α) w keeps its component along ω2 (from v) and along ω1 (from w):
  // u = c1 ω1 + c2 ω2 + c3 (ω1 x ω2), |u| = |v|.
  const double g = w1.dot(w2);
  const Eigen::Vector3d n = w1.cross(w2);
  const double det = 1 - g * g;
  const double p1 = w1.dot(w), p2 = w2.dot(v);
  const double c1 = (p1 - g * p2) / det, c2 = (p2 - g * p1) / det;
  const Eigen::Vector3d base = c1 * w1 + c2 * w2;
  const double rest = v.squaredNorm() - base.squaredNorm();
  const double nn = n.squaredNorm();
  TwoRotationsPair out;
  const double tiny = 1e-12;
  if (rest < -tiny) return out;  // the tilt needed is beyond what the two axes can reach
  const double c3 = std::sqrt(std::max(0.0, rest) / nn);
  for (double sign : {1.0, -1.0}) {
    if (sign < 0 && c3 * std::sqrt(nn) < 1e-12) break;  // a double root: one solution
    const Eigen::Vector3d u = base + sign * c3 * n;
    TwoRotations& s = out.items[size_t(out.count++)];
    s.beta = angle_about(w2, v, u, s.beta_free);
    s.alpha = angle_about(w1, u, w, s.alpha_free);
  }
  return out;
}
}  // namespace

std::vector<TwoRotations> solve_two_rotations(const Eigen::Vector3d& w1, const Eigen::Vector3d& w2, const Eigen::Vector3d& v,
                                              const Eigen::Vector3d& w) {
  const TwoRotationsPair p = two_rotations(w1, w2, v, w);
  return {p.items.begin(), p.items.begin() + p.count};
}

namespace {
// The machine's orientation equation H k0 = T k as R(ω1, α) R(ω2, β) v = w, and how α, β map to
// the rotary joints (sign of α).
struct OrientationProblem {
  Eigen::Vector3d w1, w2, v, w;
  double alpha_sign = 1;
};
OrientationProblem orientation_problem(const Machine& m, const Eigen::Vector3d& axis_part) {
  const Eigen::Vector3d k = axis_part.normalized(), k0 = m.spindle_direction;
  const Eigen::Vector3d &d0 = m.rotary[0].direction, &d1 = m.rotary[1].direction;
  switch (m.tables()) {
    case 2: return {d0, d1, k, k0, 1};    // R(t0) R(t1) k = k0
    case 0: return {d0, d1, k0, k, 1};    // R(h0) R(h1) k0 = k
    default: return {d0, d1, k0, k, -1};  // rotary[0] is the table: R(t, -θt) R(h, θh) k0 = k
  }
}
}  // namespace

RotarySolutionPair rotary_solution_pair(const Machine& m, const Eigen::Vector3d& axis_part) {
  const OrientationProblem p = orientation_problem(m, axis_part);
  const TwoRotationsPair t = two_rotations(p.w1, p.w2, p.v, p.w);
  RotarySolutionPair out;
  for (int i = 0; i < t.count; ++i) {
    const TwoRotations& s = t.items[size_t(i)];
    out.items[size_t(out.count++)] = {{wrap180(p.alpha_sign * s.alpha / kDeg), wrap180(s.beta / kDeg)}, {s.alpha_free, s.beta_free}};
  }
  return out;
}

std::vector<RotarySolution> rotary_solutions(const Machine& m, const Eigen::Vector3d& axis_part) {
  const RotarySolutionPair p = rotary_solution_pair(m, axis_part);
  return {p.begin(), p.end()};
}

double singularity_cosine(const Machine& m, const Eigen::Vector3d& axis_part) {
  const OrientationProblem p = orientation_problem(m, axis_part);
  const auto cosine = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::min(1.0, std::abs(a.normalized().dot(b.normalized())));
  };
  return std::max(cosine(p.v, p.w2), cosine(p.w, p.w1));
}

double singularity_angle_deg(const Machine& m, const Eigen::Vector3d& axis_part) {
  return std::acos(singularity_cosine(m, axis_part)) / kDeg;
}

PreparedForward prepare_forward(const Machine& m, double tool_length) {
  PreparedForward f;
  for (size_t k = 0; k < 2; ++k) {
    const RotaryAxis& a = m.rotary[k];
    f.direction[k] = a.direction;
    f.table[k] = a.carries == Carrier::Table;
    f.centre[k] = f.table[k] ? a.pivot : Eigen::Vector3d(a.pivot + (m.gauge_length_mm + tool_length) * m.spindle_direction);
  }
  f.spindle = m.spindle_direction;
  return f;
}

Eigen::Vector3d linear_joints(const Machine& m, const ToolPose& pose, const std::array<double, 2>& deg, double tool_length) {
  // Machine position of the tip: T(tip_part); the tip relative to the controlled point: H(0).
  const Chains c = chains(m, deg, tool_length);
  return c.table.apply(pose.tip) - c.head.t;
}

Eigen::Vector3d linear_joints(const Machine& m, const ToolPose& pose, const std::array<double, 2>& cos_deg,
                              const std::array<double, 2>& sin_deg, double tool_length) {
  const Chains c = chains(m, cos_deg, sin_deg, tool_length);
  return c.table.apply(pose.tip) - c.head.t;
}

TableTransform table_transform(const Machine& m, const std::array<double, 2>& deg) {
  const Chains c = chains(m, deg, 0);
  return {c.table.R, c.table.t};
}

ToolPose forward(const Machine& m, const Joints& q, double tool_length) {
  const Chains c = chains(m, q.rotary, tool_length);
  ToolPose p;
  p.tip = c.table.apply_inverse(q.linear + c.head.t);
  p.axis = c.table.R.transpose() * (c.head.R * m.spindle_direction);
  return p;
}

std::vector<Joints> inverse(const Machine& m, const ToolPose& pose, double tool_length) {
  std::vector<Joints> out;
  for (const RotarySolution& s : rotary_solutions(m, pose.axis)) {
    Joints q;
    q.rotary = s.deg;
    q.linear = linear_joints(m, pose, s.deg, tool_length);
    out.push_back(q);
  }
  return out;
}

}  // namespace flankcam
