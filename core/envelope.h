// Envelopes of a moving canal surface (a tool: spheres of radius d(s) centred on
// the axis segment c(s,t) = (1-s) a(t) + s b(t)). The envelope of the
// two-parameter sphere family is x = c + d n with |n| = 1, n·c_s = -d'(s) and
// n·c_t = 0 (two solutions: the sheets). Used as ground truth (exact envelopes of
// analytic motions) and to build the surface a fitted motion really machines.
#pragma once
#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "core/bspline.h"
#include "core/mesh.h"

namespace flankcam {

// Motion of the axis segment a(t) -> b(t), t in [0, 1], with velocities. mm.
struct LineMotion {
  std::function<Eigen::Vector3d(double)> a, b, da, db;
};

// A motion given by positions only; velocities by 4th-order central differences.
[[nodiscard]] LineMotion motion_from_positions(std::function<Eigen::Vector3d(double)> a,
                                               std::function<Eigen::Vector3d(double)> b);
// A motion whose rails are cubic B-splines (the fitted axis).
[[nodiscard]] LineMotion motion_from_rails(const BSpline& a, const BSpline& b);

// d(s), s in [0, 1] along a->b, as a 1D cubic B-spline in mm.
struct RadiusProfile {
  BSpline radius;
  [[nodiscard]] double d(double s) const { return radius.value(s, 0); }
  [[nodiscard]] double d_s(double s) const { return radius.value(s, 1); }
};
[[nodiscard]] RadiusProfile cylinder_profile(double r);
[[nodiscard]] RadiusProfile cone_profile(double r0, double r1);             // linear r0 at a, r1 at b
[[nodiscard]] RadiusProfile barrel_profile(double r_end, double bulge);      // r_end + bulge·4s(1-s)
[[nodiscard]] RadiusProfile spline_profile(const std::vector<double>& ctrl);  // control values, mm

struct EnvelopePoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // sphere normal n: from the axis to the envelope
  bool valid = false;                                // false where the characteristic does not exist
};
// sheet = +1 or -1 picks the solution n = x e1 + y e2 + sheet·z e3, e3 = c_s × c_t (normalised, Gram-Schmidt).
[[nodiscard]] EnvelopePoint envelope_point(const Eigen::Vector3d& c, const Eigen::Vector3d& c_s,
                                           const Eigen::Vector3d& c_t, double d, double d_s, int sheet);

struct EnvelopeGrid {
  TriMesh mesh;                        // vertex (i, j) = i * n_s + j: t_i, s_j; faces oriented away from the tool
  std::vector<char> valid;             // per vertex
  int n_s = 0, n_t = 0;
  int invalid_points = 0;
  int folded_triangles = 0;            // faces whose normal disagrees with the sphere normal (sheet folds)
  std::vector<char> folded;            // per face: 1 for those
};
// Samples the envelope on a uniform (t, s) grid over [t0, t1] x [s0, 1]. Faces touching an invalid
// point are left out. s0 > 0: the side above a rounded tool end (core/tool_end.h).
[[nodiscard]] EnvelopeGrid envelope_grid(const LineMotion& motion, const RadiusProfile& profile, int n_s, int n_t,
                                         int sheet, double t0 = 0.0, double t1 = 1.0, double s0 = 0.0);

// Analytic motions for ground truth, all rigid (|b - a| = length), mm.
struct AnalyticMotionOptions {
  std::string kind = "twist";  // twist | arc | helix | s-curve
  double length = 40.0;        // axis segment length L, mm
  double travel = 120.0;       // characteristic size of the path, mm
  double twist_deg = 30.0;     // rotation of the axis over the motion, degrees
};
[[nodiscard]] LineMotion analytic_motion(const AnalyticMotionOptions& o);
// Throws InputError naming the bad field.
void validate(const AnalyticMotionOptions& o);

}  // namespace flankcam
