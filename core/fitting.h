// Fitting the envelope of a moving surface of revolution to a design surface
// (paper Sec. 4.4-4.6). Everything here works in the unit-diagonal frame of Φ:
// lengths are relative to Φ's bounding-box diagonal.
#pragma once
#include <Eigen/Core>
#include <array>
#include <functional>
#include <string>
#include <vector>

#include "core/bspline.h"
#include "core/closest_point.h"
#include "core/envelope.h"
#include "core/movability.h"

namespace flankcam {

enum class ToolShape { General, Cone, Cylinder };
[[nodiscard]] const char* to_string(ToolShape s);
[[nodiscard]] ToolShape tool_shape_from_string(const std::string& s);  // throws InputError

struct FitOptions {
  int samples_s = 30, samples_t = 100;                            // n x m samples of R(t, s) (paper: 30 x 100)
  double w_plane = 1, w_fair = 0.1, w_point = 0.001, w_rigid = 0.1;  // μ1..μ4 of eq. (12)
  // true: F_fair (eq. 11) acts on each round's change of the rails, so it keeps the updates fair
  // without pulling a curved motion straight; false: on the rails themselves, as printed in the
  // paper (this biases curved exact envelopes by more than 1e-4 of the diagonal).
  bool fair_update = true;
  // Weak pull of the radii d_j to the initial meridian (not in the paper): fixes the nearly free
  // offset of axis and radius on nearly developable surfaces. 0 disables it.
  double w_anchor = 1e-4;
  ToolShape shape = ToolShape::General;
  int rail_control_points = 16;      // per rail a(t), b(t)
  int meridian_control_points = 10;  // general tools: cubic spline d(s) (paper: 10)
  int max_iterations = 25;           // outer iterations (footpoints recomputed between solves)
  int solver_iterations = 5;         // Levenberg-Marquardt iterations per outer iteration
  double stall = 2e-2;               // stop when a round lowers its objective by less than this, relatively
  // or when a round moves the envelope by less than this at every sample (unit frame). 1e-6 stops the
  // exact-envelope tests 2-12 rounds earlier but raises their ε by up to 15%, so the default only
  // stops a fit that has really stalled.
  double motion_tolerance = 1e-7;
  // Scale of a Cauchy loss on the sample residuals (unit frame; not in the paper). Samples whose
  // distance error is well above it (a local bump, a damaged scan) stop pulling the motion, so the
  // fit stays on the rest. The price is a larger worst error where the surface is simply not an
  // envelope: on rotor 37 a scale of 1e-3 raised the worst overcut from 0.11 to 0.15 mm (1e-4: 0.43 mm)
  // while coverage rose from 61% to 62% (72%). 0: plain least squares, as in the paper.
  double robust_scale = 0;
  int threads = 2;
  // Called after each outer iteration with its number (1-based) and F_motion; may be empty.
  std::function<void(int iteration, double objective)> on_iteration;
  std::string validate() const;      // empty when valid, else names the field
};

// The axis motion: rails a(t) (tool tip side, s = 0) and b(t) (s = 1), cubic B-splines,
// and the rigid length L the rigidity term keeps.
struct Rails {
  BSpline a, b;
  double length = 0;
  [[nodiscard]] Eigen::Vector3d point(double t, double s) const { return (1 - s) * a.point(t) + s * b.point(t); }
};
[[nodiscard]] LineMotion to_motion(const Rails& r);

// A finite line [a, b] (unit frame).
struct AxisLine {
  Eigen::Vector3d a, b;
};

// Surface-driven initialisation (Sec. 4.4): the endpoints of the ordered user lines are the
// control polygons of two cubic B-splines; the trajectory of `rail` (0: a, 1: b) and the
// length L (<= 0: mean length of the lines) give a rigid motion, refitted with
// `rail_control_points` control points.
[[nodiscard]] Rails rails_from_lines(const std::vector<AxisLine>& lines, int rail, double length,
                                     const FitOptions& options);
// Line-driven: the rails through the positions of a propagated line (Sec. 4.3).
[[nodiscard]] Rails rails_from_trajectory(const LineTrajectory& trajectory, const FitOptions& options);

// Tool radii along the axis: d(s) = sum_k c_k(s) D_k, with c the shape's basis
// (general: cubic spline with meridian_control_points values; cone: linear; cylinder: constant).
struct ToolRadius {
  ToolShape shape = ToolShape::General;
  std::vector<double> D;  // parameters, unit frame
  [[nodiscard]] std::vector<double> basis(double s) const;
  [[nodiscard]] double d(double s) const;
  [[nodiscard]] RadiusProfile profile() const;  // the same d(s) as a cubic B-spline
};

struct ErrorStats {
  double max = 0, mean = 0;     // eq. (13) over the samples, unit frame (= relative to the diagonal)
  int samples = 0, excluded = 0;  // excluded: footpoint on Φ's boundary (the axis point is beyond Φ)
  std::vector<double> bin_edges;  // histogram of |dist - d_j| (unit frame)
  std::vector<int> histogram;
};
// ε of eq. (13): max_ij |dist(R(t_i, s_j), Φ) - d_j| (the paper prints "min"; it means the worst sample).
[[nodiscard]] ErrorStats sample_error(const SurfaceIndex& surface, const Rails& rails, const ToolRadius& tool,
                                      const FitOptions& options);

// Initial radii (Sec. 4.5, meridian update): footpoints of the samples mapped to the common
// (axial, radial) plane, a least-squares spline (or line, or constant) meridian through them, and
// d_j = distance of the axis point to that meridian.
[[nodiscard]] ToolRadius initial_tool(const SurfaceIndex& surface, const Rails& rails, const FitOptions& options);

// The half-meridian in the tool's own frame (z along a->b from a, r radial): the planar
// envelope of the circles (z, d(z)); unit frame.
[[nodiscard]] std::vector<Eigen::Vector2d> meridian(const ToolRadius& tool, double length, int points = 61);

enum class FitStatus {
  Converged,       // the motion and radii stopped moving, or a round could not lower F_motion
  IterationLimit,  // max_iterations outer rounds ran
  SolverFailed,    // Ceres reported FAILURE (or a cost that is not finite); the last good motion is kept
};
[[nodiscard]] const char* to_string(FitStatus s);

struct FitResult {
  Rails rails;
  ToolRadius tool;
  ErrorStats eps_ini, eps_opt;
  int iterations = 0;
  std::vector<double> objective;  // F_motion, eq. (12), after each outer iteration
  bool converged = false;  // status == Converged
  FitStatus status = FitStatus::IterationLimit;
  std::string message;  // why the solver failed (SolverFailed), else empty
};
// Joint optimisation of the rails and the radii (eqs. 8-12) from an initial motion.
[[nodiscard]] FitResult optimize_motion(const SurfaceIndex& surface, const Rails& initial, const FitOptions& options);

}  // namespace flankcam
