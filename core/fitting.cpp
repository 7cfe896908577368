#include "core/fitting.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>

#include "core/collision.h"
#include "core/errors.h"
#include "core/fitting_residuals.h"
#include "core/tool_end.h"

namespace flankcam {

using fit_residuals::LinearResidual;
using fit_residuals::RigidResidual;
using fit_residuals::SampleResidual;

const char* to_string(FitStatus s) {
  switch (s) {
    case FitStatus::Converged: return "converged";
    case FitStatus::IterationLimit: return "iteration limit";
    case FitStatus::SolverFailed: return "solver failed";
  }
  return "?";
}

const char* to_string(ToolShape s) {
  switch (s) {
    case ToolShape::General: return "general";
    case ToolShape::Cone: return "cone";
    case ToolShape::Cylinder: return "cylinder";
  }
  return "?";
}

ToolShape tool_shape_from_string(const std::string& s) {
  if (s == "general") return ToolShape::General;
  if (s == "cone") return ToolShape::Cone;
  if (s == "cylinder") return ToolShape::Cylinder;
  throw InputError("tool shape '" + s + "' is not one of general, cone, cylinder");
}

std::string FitOptions::validate() const {
  if (samples_s < 4) return "sampling.s: at least 4 samples along the axis";
  if (samples_t < 8) return "sampling.t: at least 8 samples along the motion";
  for (double w : {w_plane, w_fair, w_point, w_rigid})
    if (!(w >= 0) || !std::isfinite(w)) return "weights: must be finite and >= 0";
  if (!(w_plane > 0 || w_point > 0)) return "weights: plane or point must be positive";
  if (!(w_anchor >= 0) || !std::isfinite(w_anchor)) return "weights.anchor: must be finite and >= 0";
  if (rail_control_points < 4) return "rail_control_points: at least 4";
  if (rail_control_points * 2 > samples_t) return "rail_control_points: at most half of sampling.t";
  if (meridian_control_points < 4 || meridian_control_points > samples_s) return "meridian_control_points: 4 .. sampling.s";
  if (max_iterations < 1) return "max_iterations: at least 1";
  if (solver_iterations < 1) return "solver_iterations: at least 1";
  if (!(stall >= 0)) return "stall: must be >= 0";
  if (!(motion_tolerance >= 0) || !std::isfinite(motion_tolerance)) return "motion_tolerance: must be finite and >= 0";
  if (!(plateau >= 0 && plateau < 1)) return "plateau: must be in [0, 1)";
  if (plateau_rounds < 0) return "plateau_rounds: must be >= 0";
  if (!(robust_scale >= 0) || !std::isfinite(robust_scale)) return "robust_scale: must be finite and >= 0";
  if (!(w_constraint >= 0) || !std::isfinite(w_constraint)) return "w_constraint: must be finite and >= 0";
  if (auto err = constraints.validate(); !err.empty()) return err;
  if (check.part) {
    for (double v : {check.tolerance, check.clearance, check.band})
      if (!(v >= 0) || !std::isfinite(v)) return "check: tolerance, clearance and band must be finite and >= 0";
    if (!(check.weight > 0) || !std::isfinite(check.weight)) return "check.weight: must be finite and > 0";
    if (!(check.depth_limit > 0 && check.depth_limit <= 1)) return "check.depth_limit: must be in (0, 1]";
    for (const Eigen::Vector2d& b : check.body)
      if (!(b.x() >= 0 && b.y() >= 0) || !b.allFinite()) return "check.body: samples must be finite with u, radius >= 0";
  }
  if (threads < 1) return "threads: at least 1";
  return {};
}

LineMotion to_motion(const Rails& r) { return motion_from_rails(r.a, r.b); }

Eigen::Vector3d mean_axis(const Rails& r) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i = 0; i <= 20; ++i) mean += (r.b.point(i / 20.0) - r.a.point(i / 20.0)).normalized();
  return mean;
}

namespace {

constexpr double kMaxOverhang = 0.05;  // tangential overhang over distance for boundary samples (~3 degrees)

BSpline fit_rail(const std::vector<Eigen::Vector3d>& pts, const std::vector<double>& ts, int n_ctrl) {
  Eigen::MatrixXd P(Eigen::Index(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) P.row(Eigen::Index(i)) = pts[i].transpose();
  return fit_bspline(P, ts, n_ctrl, 0.0);
}

// Cubic B-spline through the ordered points (chord-length parameters, one control point per
// point, so it interpolates them); fewer than 4 points are first densified along the polygon.
BSpline spline_through(std::vector<Eigen::Vector3d> poly, const std::vector<double>& ts_in) {
  std::vector<double> ts = ts_in;
  if (poly.size() < 4) {
    std::vector<Eigen::Vector3d> out;
    std::vector<double> out_t;
    for (int k = 0; k < 4; ++k) {
      const double u = double(k) / 3 * double(poly.size() - 1);
      const size_t i = std::min(size_t(u), poly.size() - 2);
      out.push_back(poly[i] + (u - double(i)) * (poly[i + 1] - poly[i]));
      out_t.push_back(ts[i] + (u - double(i)) * (ts[i + 1] - ts[i]));
    }
    poly = out;
    ts = out_t;
  }
  return fit_rail(poly, ts, int(poly.size()));
}

// Footpoints of the m x n samples R(t_i, s_j), row-major in i.
std::vector<Footpoint> sample_footpoints(const SurfaceIndex& surface, const Rails& rails, int m, int n) {
  std::vector<Eigen::Vector3d> pts(size_t(m) * n);
  for (int i = 0; i < m; ++i) {
    const double t = double(i) / (m - 1);
    const Eigen::Vector3d a = rails.a.point(t), b = rails.b.point(t);
    for (int j = 0; j < n; ++j) {
      const double s = double(j) / (n - 1);
      pts[size_t(i) * n + j] = (1 - s) * a + s * b;
    }
  }
  return surface.closest(pts);
}

// The unit normal n_ij of a sample's footpoint plane, oriented towards p, or nothing when
// the sample has no data. Inside Φ it is (p - p⊥)/|p - p⊥|, the gradient of the distance (the
// interpolated vertex normal would tilt it by up to half the angle between faces and bias the
// fit). At a boundary footpoint the sample may hang over the edge: it keeps the surface's
// tangent plane there (a first-order continuation of Φ) while the overhang is small, else it
// is left out. Dropping every boundary sample instead would let the optimiser lower its
// objective by pushing samples over the edge.
std::optional<Eigen::Vector3d> sample_plane(const Eigen::Vector3d& p, const Footpoint& f) {
  const Eigen::Vector3d r = p - f.point;
  const double dist = r.norm();
  if (!f.on_boundary) return dist > 1e-12 ? Eigen::Vector3d(r / dist) : f.normal;
  const Eigen::Vector3d n = r.dot(f.normal) >= 0 ? f.normal : Eigen::Vector3d(-f.normal);
  const double along = r.dot(n);
  if (!(along > 0) || (r - along * n).norm() > kMaxOverhang * along) return std::nullopt;
  return n;
}

int shape_parameters(ToolShape shape, const FitOptions& o) {
  switch (shape) {
    case ToolShape::General: return o.meridian_control_points;
    case ToolShape::Cone: return 2;
    case ToolShape::Cylinder: return 1;
  }
  return 1;
}

}  // namespace

Rails rails_from_lines(const std::vector<AxisLine>& lines, int rail, double length, const FitOptions& o) {
  if (lines.size() < 2) throw InputError("lines: surface-driven initialisation needs at least 2 lines");
  std::vector<Eigen::Vector3d> pa, pb;
  double mean_length = 0;
  for (const auto& l : lines) {
    pa.push_back(l.a);
    pb.push_back(l.b);
    mean_length += (l.b - l.a).norm() / double(lines.size());
  }
  if (!(mean_length > 0)) throw InputError("lines: the axis lines have zero length");
  const double L = length > 0 ? length : mean_length;
  // The paper uses the endpoints as control polygons; users give positions the axis should take,
  // so the rails interpolate them (chord-length parameters of the midpoints).
  Eigen::MatrixXd mids(Eigen::Index(lines.size()), 3);
  for (size_t k = 0; k < lines.size(); ++k) mids.row(Eigen::Index(k)) = (0.5 * (pa[k] + pb[k])).transpose();
  const std::vector<double> tl = chord_length_parameters(mids);
  const BSpline sa = spline_through(pa, tl), sb = spline_through(pb, tl);
  const int samples = std::max(4 * o.samples_t, 200);
  std::vector<Eigen::Vector3d> A, B;
  const std::vector<double> ts = uniform_parameters(samples);
  for (double t : ts) {
    const Eigen::Vector3d a = sa.point(t), b = sb.point(t);
    const Eigen::Vector3d dir = (b - a).normalized();
    if (rail == 0) {
      A.push_back(a);
      B.push_back(a + L * dir);
    } else {
      A.push_back(b - L * dir);
      B.push_back(b);
    }
  }
  return {fit_rail(A, ts, o.rail_control_points), fit_rail(B, ts, o.rail_control_points), L};
}

std::vector<double> trajectory_parameters(const LineTrajectory& tr) {
  Eigen::MatrixXd mids(Eigen::Index(tr.a.size()), 3);
  for (size_t k = 0; k < tr.a.size(); ++k) mids.row(Eigen::Index(k)) = (0.5 * (tr.a[k] + tr.b[k])).transpose();
  return chord_length_parameters(mids);
}

Rails rails_from_trajectory(const LineTrajectory& tr, const FitOptions& o) {
  if (tr.a.size() < size_t(o.rail_control_points))
    throw InputError("line propagation produced only " + std::to_string(tr.a.size()) +
                     " positions: the line is not movable along the surface (try another line)");
  const std::vector<double> ts = trajectory_parameters(tr);
  return {fit_rail(tr.a, ts, o.rail_control_points), fit_rail(tr.b, ts, o.rail_control_points),
          (tr.b[0] - tr.a[0]).norm()};
}

std::vector<double> ToolRadius::basis(double s) const {
  const int K = int(D.size());
  std::vector<double> c(size_t(K), 0.0);
  if (shape == ToolShape::General) {
    const BasisRow r = bspline_basis(K, s);
    for (int k = 0; k < 4; ++k) c[size_t(r.first + k)] = r.w[k];
  } else if (shape == ToolShape::Cone) {
    c = {1 - s, s};
  } else {
    c = {1.0};
  }
  return c;
}

double ToolRadius::d(double s) const {
  const std::vector<double> c = basis(s);
  return std::inner_product(c.begin(), c.end(), D.begin(), 0.0);
}

RadiusProfile ToolRadius::profile() const {
  if (shape == ToolShape::General) return spline_profile(D);
  if (shape == ToolShape::Cone) return cone_profile(D[0], D[1]);
  return cylinder_profile(D[0]);
}

ToolRadius initial_tool(const SurfaceIndex& surface, const Rails& rails, const FitOptions& o) {
  const int m = o.samples_t, n = o.samples_s;
  const auto fps = sample_footpoints(surface, rails, m, n);
  // Footpoints in the common (axial, radial) plane of the moving axis.
  std::vector<Eigen::Vector2d> zr;
  for (int i = 0; i < m; ++i) {
    const double t = double(i) / (m - 1);
    const Eigen::Vector3d a = rails.a.point(t), b = rails.b.point(t);
    const double len = (b - a).norm();
    const Eigen::Vector3d e = (b - a) / len;
    for (int j = 0; j < n; ++j) {
      const Footpoint& f = fps[size_t(i) * n + j];
      if (f.on_boundary) continue;  // meridian from interior footpoints only
      const Eigen::Vector3d q = f.point - a;
      const double z = q.dot(e) * rails.length / len;
      zr.emplace_back(z, (q - q.dot(e) * e).norm());
    }
  }
  if (zr.size() < size_t(2 * n))
    throw InputError("the initial motion is not over the design surface: almost all footpoints lie on its boundary");
  ToolRadius tool;
  tool.shape = o.shape;
  const int K = shape_parameters(o.shape, o);
  std::vector<double> d(static_cast<size_t>(n));
  const double L = rails.length;
  if (o.shape == ToolShape::General) {
    // Least-squares cubic meridian r(z) with K control points over the footpoints' z range.
    double zmin = INFINITY, zmax = -INFINITY;
    for (const auto& p : zr) zmin = std::min(zmin, p.x()), zmax = std::max(zmax, p.x());
    if (!(zmax > zmin)) zmax = zmin + L;
    std::vector<Eigen::Vector2d> sorted_zr = zr;
    std::sort(sorted_zr.begin(), sorted_zr.end(), [](const auto& p, const auto& q) { return p.x() < q.x(); });
    Eigen::MatrixXd R(Eigen::Index(sorted_zr.size()), 1);
    std::vector<double> us;
    for (size_t k = 0; k < sorted_zr.size(); ++k) {
      us.push_back((sorted_zr[k].x() - zmin) / (zmax - zmin));
      R(Eigen::Index(k), 0) = sorted_zr[k].y();
    }
    const BSpline meridian_spline = fit_bspline(R, us, K, 1e-6);
    std::vector<Eigen::Vector2d> curve;
    for (int k = 0; k <= 800; ++k) {
      const double u = k / 800.0;
      curve.emplace_back(zmin + u * (zmax - zmin), meridian_spline.value(u));
    }
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector2d c(L * j / (n - 1), 0.0);
      double best = INFINITY;
      for (const auto& p : curve) best = std::min(best, (p - c).norm());
      d[size_t(j)] = best;
    }
  } else {
    // Line (cone) or constant (cylinder) meridian r = α + β z by least squares.
    Eigen::MatrixXd M(Eigen::Index(zr.size()), o.shape == ToolShape::Cone ? 2 : 1);
    Eigen::VectorXd r(Eigen::Index(zr.size()));
    for (size_t k = 0; k < zr.size(); ++k) {
      M(Eigen::Index(k), 0) = 1;
      if (o.shape == ToolShape::Cone) M(Eigen::Index(k), 1) = zr[k].x();
      r[Eigen::Index(k)] = zr[k].y();
    }
    const Eigen::VectorXd coef = M.colPivHouseholderQr().solve(r);
    const double beta = o.shape == ToolShape::Cone ? coef[1] : 0.0;
    for (int j = 0; j < n; ++j) d[size_t(j)] = (coef[0] + beta * L * j / (n - 1)) / std::sqrt(1 + beta * beta);
  }
  // Parameters D of the shape's basis from the d_j, least squares.
  tool.D.assign(size_t(K), 0.0);
  Eigen::MatrixXd C(n, K);
  Eigen::VectorXd dj(n);
  for (int j = 0; j < n; ++j) {
    const std::vector<double> c = tool.basis(double(j) / (n - 1));
    for (int k = 0; k < K; ++k) C(j, k) = c[size_t(k)];
    dj[j] = d[size_t(j)];
  }
  const Eigen::VectorXd D = C.colPivHouseholderQr().solve(dj);
  for (int k = 0; k < K; ++k) tool.D[size_t(k)] = D[k];
  return tool;
}

std::vector<Eigen::Vector2d> cutter_union(const ToolRadius& tool, double length, int points) {
  const int ns = 1024;
  std::vector<double> d(ns + 1);
  for (int k = 0; k <= ns; ++k) d[size_t(k)] = tool.d(double(k) / ns);
  std::vector<Eigen::Vector2d> out;
  for (int i = 0; i < points; ++i) {
    const double z = length * i / (points - 1);
    const auto r2 = [&](double s) { const double dz = z - s * length, ds = tool.d(s); return ds * ds - dz * dz; };
    int best = 0;
    for (int k = 1; k <= ns; ++k) {
      const double dz = z - length * k / ns, dz0 = z - length * best / ns;
      if (d[size_t(k)] * d[size_t(k)] - dz * dz > d[size_t(best)] * d[size_t(best)] - dz0 * dz0) best = k;
    }
    // Refined by golden section between the neighbouring samples (r2 is unimodal there).
    double lo = std::max(0, best - 1) / double(ns), hi = std::min(ns, best + 1) / double(ns);
    const double g = 0.5 * (std::sqrt(5.0) - 1);
    for (int it = 0; it < 40; ++it) {
      const double a = hi - g * (hi - lo), b = lo + g * (hi - lo);
      if (r2(a) < r2(b)) lo = a; else hi = b;
    }
    const double best_r2 = std::max({r2(0.5 * (lo + hi)), r2(double(best) / ns)});
    out.emplace_back(z, std::sqrt(std::max(0.0, best_r2)));
  }
  return out;
}

std::vector<Eigen::Vector2d> meridian(const ToolRadius& tool, double length, int points) {
  const RadiusProfile p = tool.profile();
  std::vector<Eigen::Vector2d> out;
  for (int k = 0; k < points; ++k) {
    const double s = double(k) / (points - 1);
    const double d = p.d(s), dz = p.d_s(s) / length;  // d'(z)
    const double z = s * length - d * dz;               // envelope of the circles (z, d(z))
    out.emplace_back(z, d * std::sqrt(std::max(0.0, 1 - dz * dz)));
  }
  return out;
}

std::optional<ToolDefect> tool_defect(const ToolRadius& tool, double length) {
  const RadiusProfile p = tool.profile();
  const int n = 240;
  double z_before = -INFINITY, d_most = 0;
  for (int k = 0; k <= n; ++k) {
    const double s = double(k) / n;
    const double d = p.d(s), dz = p.d_s(s) / length;
    d_most = std::max(d_most, d);
    if (!(d > 0)) return ToolDefect{s, "its radius reaches 0"};
    if (!(std::abs(dz) < 1)) return ToolDefect{s, "its radius changes faster than its length (no meridian)"};
    const double z = s * length - d * dz;  // as meridian()
    if (!(z > z_before)) return ToolDefect{s, "its meridian turns back on itself"};
    z_before = z;
  }
  // A needle: the fit may shrink a cylinder until its axis lies in Φ (HECC diffuser: Ø0.009 mm over
  // 19.9 mm), which no shop can make nor cut with.
  if (length > kMaxSlenderness * 2 * d_most)
    return ToolDefect{0.5, fmt::format("it is {:.0f} times as long as its largest diameter (at most {:.0f}: no tool that "
                                       "slender can be made or cut with)",
                                       length / (2 * d_most), kMaxSlenderness)};
  return std::nullopt;
}

namespace {
// ε of eq. (13) from the footpoints of the m x n samples (row-major); the histogram only when asked.
ErrorStats footpoint_error(const std::vector<Footpoint>& fps, const ToolRadius& tool, int m, int n, bool histogram) {
  ErrorStats e;
  std::vector<double> errs;
  errs.reserve(fps.size());
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < n; ++j) {
      const Footpoint& f = fps[size_t(i) * n + j];
      if (f.on_boundary) {  // the footpoint is on Φ's rim: the sample is beyond Φ, not an error of it
        ++e.excluded;
        continue;
      }
      errs.push_back(std::abs(f.distance - tool.d(double(j) / (n - 1))));
    }
  e.samples = int(errs.size());
  if (errs.empty()) return e;
  e.max = *std::max_element(errs.begin(), errs.end());
  e.mean = std::accumulate(errs.begin(), errs.end(), 0.0) / double(errs.size());
  if (!histogram) return e;
  const int bins = 10;
  e.histogram.assign(bins, 0);
  for (int k = 0; k <= bins; ++k) e.bin_edges.push_back(e.max * k / bins);
  for (double x : errs) ++e.histogram[std::min(bins - 1, e.max > 0 ? int(x / e.max * bins) : 0)];
  return e;
}
}  // namespace

ErrorStats sample_error(const SurfaceIndex& surface, const Rails& rails, const ToolRadius& tool, const FitOptions& o) {
  return footpoint_error(sample_footpoints(surface, rails, o.samples_t, o.samples_s), tool, o.samples_t, o.samples_s, true);
}

bool fit_plateaued(const std::vector<RoundMeasures>& history, double progress, int rounds) {
  const size_t k = history.size();
  if (rounds < 1 || k <= size_t(rounds)) return false;
  const size_t first = k - size_t(rounds);
  RoundMeasures best = history.front();
  for (size_t r = 1; r < first; ++r) {
    best.objective = std::min(best.objective, history[r].objective);
    best.eps = std::min(best.eps, history[r].eps);
    best.mean_error = std::min(best.mean_error, history[r].mean_error);
  }
  const double keep = 1 - progress;
  for (size_t r = first; r < k; ++r)
    if (history[r].objective < keep * best.objective || history[r].eps < keep * best.eps ||
        history[r].mean_error < keep * best.mean_error)
      return false;
  return true;
}

bool ToolConstraints::active() const {
  return min_radius > 0 || std::isfinite(max_radius) || std::isfinite(max_length) || min_tip_radius > 0 ||
         std::isfinite(max_tip_radius) || min_ball_radius > 0 || max_cone_angle_rad < M_PI / 2 || convex;
}

std::string ToolConstraints::validate() const {
  if (!(min_radius >= 0) || !std::isfinite(min_radius)) return "tool.min_diameter: must be finite and >= 0";
  if (!(max_radius > 0)) return "tool.max_diameter: must be > 0";
  if (!(min_tip_radius >= 0) || !std::isfinite(min_tip_radius)) return "tool.min_tip_diameter: must be finite and >= 0";
  if (!(max_length > 0)) return "tool.max_length: must be > 0";
  if (!(max_cone_angle_rad >= 0 && max_cone_angle_rad <= M_PI / 2)) return "tool.max_cone_angle: must be in 0 .. 90 deg";
  if (min_radius > max_radius) return "tool.min_diameter: larger than tool.max_diameter";
  if (min_tip_radius > max_radius) return "tool.min_tip_diameter: larger than tool.max_diameter";
  if (!(max_tip_radius > 0)) return "tool.max_tip_diameter: must be > 0";
  if (min_tip_radius > max_tip_radius) return "tool.min_tip_diameter: larger than tool.max_tip_diameter";
  if (min_radius > max_tip_radius) return "tool.min_diameter: larger than tool.max_tip_diameter";
  if (!(min_ball_radius >= 0) || !std::isfinite(min_ball_radius)) return "tool.end.corner: must be finite and >= 0";
  if (min_ball_radius > max_radius) return "tool.end.corner: larger than half of tool.max_diameter";
  return {};
}

namespace {
// Q with (Q D)_k the control values of d_s(s) (derivative with respect to s): general tools
// 3 (D_{k+1} - D_k) / (u_{k+4} - u_{k+1}) over the clamped uniform knots; cones D_1 - D_0;
// cylinders none. d_s lies within their range (convex hull), so bounds on them bound the slope.
Eigen::MatrixXd slope_matrix(const ToolRadius& tool) {
  const int K = int(tool.D.size());
  if (tool.shape == ToolShape::Cylinder) return Eigen::MatrixXd(0, K);
  if (tool.shape == ToolShape::Cone) return (Eigen::MatrixXd(1, 2) << -1, 1).finished();
  const auto knot = [&](int j) { return std::clamp(double(j - 3) / (K - 3), 0.0, 1.0); };
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(K - 1, K);
  for (int k = 0; k + 1 < K; ++k) {
    const double f = 3 / (knot(k + 4) - knot(k + 1));
    Q(k, k) = -f, Q(k, k + 1) = f;
  }
  return Q;
}

// Hildreth's dual coordinate ascent: the nearest x to x0 with G x <= h (a convex QP with few rows).
Eigen::VectorXd project(const Eigen::VectorXd& x0, const Eigen::MatrixXd& G, const Eigen::VectorXd& h) {
  Eigen::VectorXd x = x0, lambda = Eigen::VectorXd::Zero(h.size());
  for (int sweep = 0; sweep < 200000; ++sweep) {
    double worst = 0;
    for (Eigen::Index k = 0; k < h.size(); ++k) {
      const double gg = G.row(k).squaredNorm();
      if (!(gg > 0)) continue;
      const double g = G.row(k).dot(x) - h[k];
      worst = std::max(worst, g);
      const double next = std::max(0.0, lambda[k] + g / gg);
      x -= (next - lambda[k]) * G.row(k).transpose();
      lambda[k] = next;
    }
    if (worst <= 1e-14) break;
  }
  return x;
}

// The rows of constraint_rows, the ball rows' axis points taken from `ball_from` (constrained_tool
// moves them with its projection).
ConstraintRows rows_at(const ToolRadius& tool, const ToolRadius& ball_from, double L, const ToolConstraints& c) {
  const int K = int(tool.D.size());
  const Eigen::MatrixXd Q = slope_matrix(tool);
  const Eigen::VectorXd D = Eigen::Map<const Eigen::VectorXd>(tool.D.data(), K);
  // Slope bound k >= |d'(z)| = |d_s| / L of the result: the cone angle's sine, and where radii r =
  // d sqrt(1 - k^2) are bounded below, also the current slope (+5%) so that d >= r_min / sqrt(1 - k^2)
  // is a sufficient bound, and small enough that this lower bound stays below max_radius.
  // A given max_cone_angle is that bound; without one the current slope is (so a tool that must taper
  // to stay out of a check surface needs max_cone_angle).
  double k = std::sin(c.max_cone_angle_rad);
  const bool lower = c.min_radius > 0 || c.min_tip_radius > 0 || c.min_ball_radius > 0;
  if (lower && !(c.max_cone_angle_rad < M_PI / 2)) {
    const double now = Q.rows() > 0 ? (Q * D).cwiseAbs().maxCoeff() / L : 0.0;
    k = std::min({k, std::max(1.05 * now, 0.02), 0.99});
    if (std::isfinite(c.max_radius)) {
      const double r = std::max({c.min_radius, c.min_tip_radius, c.min_ball_radius}) / c.max_radius;
      k = std::min(k, std::sqrt(std::max(0.0, 1 - r * r)));
    }
  }
  std::vector<Eigen::RowVectorXd> G;
  std::vector<double> h;
  const auto row = [&](Eigen::RowVectorXd g, double bound) {
    G.push_back(std::move(g));
    h.push_back(bound);
  };
  const double cosk = std::sqrt(std::max(1e-12, 1 - k * k));
  for (int i = 0; i < K; ++i) {  // d(s) lies between the smallest and largest D_k (convex hull)
    const Eigen::RowVectorXd e = Eigen::RowVectorXd::Unit(K, i);
    if (c.min_radius > 0) row(-e, -c.min_radius / cosk);
    if (std::isfinite(c.max_radius)) row(e, c.max_radius);
  }
  const auto basis_row = [&](double s) {
    const std::vector<double> b = tool.basis(s);
    return Eigen::RowVectorXd(Eigen::Map<const Eigen::RowVectorXd>(b.data(), Eigen::Index(b.size())));
  };
  // The tip's limits, at s = 0 and (either_end) at s = 1. The ball row: the meridian's end lies at
  // z0 = -d d'(z) from the end's axis point (meridian()), the ball's centre R further in, where
  // d >= R keeps the ball inside the tool. R is made larger by kBallMargin: the ball radius that
  // tool_end.h measures on a sampled meridian (61 points in the run) falls short of the smooth
  // meridian's on a curved tool (by 3e-4 R on a lens d = 3 + 12 s - 16 s^2 mm, L = 40 mm).
  const RadiusProfile from = ball_from.profile();
  const double ball = std::min(c.min_ball_radius * (1 + kBallMargin), c.max_radius);
  // The tip as ground ends in its end plane, where the spheres beyond it reach out further than d
  // there (cutter_union: a cone d0 + k z widening from its tip is d0 / sqrt(1 - k^2) wide there; a
  // cone held at d0 = 1 mm was a Ø2.018 mm tool): its bound on d is scaled by d over that width of
  // `ball_from` (constrained_tool repeats the projection until it settles, as for the ball rows),
  // at least sqrt(1 - k^2): the result's slope is within k.
  double tip_scale[2] = {1, 1};
  if (std::isfinite(c.max_tip_radius)) {
    const std::vector<Eigen::Vector2d> ends = cutter_union(ball_from, L, 2);  // z = 0 and z = L
    for (const int end : {0, 1})
      if (ends[size_t(end)].y() > 0) tip_scale[end] = std::clamp(from.d(end) / ends[size_t(end)].y(), cosk, 1.0);
  }
  for (const int end : {0, 1}) {
    if (end == 1 && !c.either_end) break;
    if (c.min_tip_radius > 0) row(-basis_row(end), -c.min_tip_radius / cosk);
    if (std::isfinite(c.max_tip_radius)) row(basis_row(end), c.max_tip_radius * tip_scale[end]);
    if (c.min_ball_radius > 0) {
      const double inward = end == 0 ? 1 : -1;  // the axis direction from this end into the tool
      const double z0 = -from.d(end) * inward * from.d_s(end) / L;
      const double s = std::clamp((z0 + ball) / L, 0.0, 1.0);
      row(-basis_row(end == 0 ? s : 1 - s), -ball);
    }
  }
  if (k < 1)
    for (Eigen::Index i = 0; i < Q.rows(); ++i) row(Q.row(i), L * k), row(-Q.row(i), L * k);
  if (c.convex)  // d_s non-increasing: d concave, no waist
    for (Eigen::Index i = 0; i + 1 < Q.rows(); ++i) row(Q.row(i + 1) - Q.row(i), 0.0);
  ConstraintRows out{Eigen::MatrixXd(Eigen::Index(G.size()), K), Eigen::VectorXd(Eigen::Index(h.size()))};
  for (size_t i = 0; i < G.size(); ++i) out.G.row(Eigen::Index(i)) = G[i], out.h[Eigen::Index(i)] = h[i];
  return out;
}
}  // namespace

ConstraintRows constraint_rows(const ToolRadius& tool, double L, const ToolConstraints& c) { return rows_at(tool, tool, L, c); }

ToolRadius constrained_tool(const ToolRadius& tool, double L, const ToolConstraints& c) {
  if (!c.active()) return tool;
  if (auto err = c.validate(); !err.empty()) throw InputError(err);
  ConstraintRows rows = constraint_rows(tool, L, c);
  ToolRadius out = tool;
  if (rows.h.size() == 0) return out;
  const Eigen::VectorXd x0 = Eigen::Map<const Eigen::VectorXd>(tool.D.data(), Eigen::Index(tool.D.size()));
  Eigen::VectorXd x = project(x0, rows.G, rows.h);
  // The ball rows' axis points and the tip's scale moved by the projection: projected again with
  // them taken from the result until they settle (they move with the tip's slope: a few rounds).
  for (int round = 0; round < 20 && (c.min_ball_radius > 0 || std::isfinite(c.max_tip_radius)); ++round) {
    out.D.assign(x.data(), x.data() + x.size());
    rows = rows_at(tool, out, L, c);
    const Eigen::VectorXd next = project(x0, rows.G, rows.h);
    const double moved = (next - x).cwiseAbs().maxCoeff();
    x = next;
    if (moved <= 1e-13 * (1 + x.cwiseAbs().maxCoeff())) break;
  }
  out.D.assign(x.data(), x.data() + x.size());
  return out;
}

namespace {
// ball_radius of a side meridian; 0 where it has none (no tip radius, too short for a ball).
double end_ball_radius(const std::vector<Eigen::Vector2d>& side) {
  try {
    return ball_radius(side);
  } catch (const InputError&) {
    return 0;
  }
}
}  // namespace

ConstraintCheck check_constraints(const ToolRadius& tool, double L, const ToolConstraints& c) {
  const std::vector<Eigen::Vector2d> mer = meridian(tool, L, 121);
  ConstraintCheck out;
  const auto note = [&](double v, const char* what) {  // rounding (a meridian at its bound) is no violation
    if (v > out.violation && v > kConstraintSlack) out.violation = v, out.what = what;
  };
  double rmin = INFINITY, rmax = 0;
  for (const auto& p : mer) rmin = std::min(rmin, p.y()), rmax = std::max(rmax, p.y());
  note(c.min_radius - rmin, "min_diameter");
  note(rmax - c.max_radius, "max_diameter");
  note(c.min_tip_radius - mer.front().y(), "min_tip_diameter");
  if (c.either_end) note(c.min_tip_radius - mer.back().y(), "min_tip_diameter");
  // The tip as ground: the tool ends in its tip plane (cutter_union), as wide there as the spheres
  // above it reach, at least the meridian's end.
  if (std::isfinite(c.max_tip_radius)) {
    const std::vector<Eigen::Vector2d> ends = cutter_union(tool, L, 2);  // z = 0 and z = L
    note(ends.front().y() - c.max_tip_radius, "max_tip_diameter");
    if (c.either_end) note(ends.back().y() - c.max_tip_radius, "max_tip_diameter");
  }
  if (c.min_ball_radius > 0) {
    note(c.min_ball_radius - end_ball_radius(mer), "end.corner");
    if (c.either_end) {
      std::vector<Eigen::Vector2d> turned;  // the meridian seen from its other end
      for (auto p = mer.rbegin(); p != mer.rend(); ++p) turned.emplace_back(mer.back().x() - p->x(), p->y());
      note(c.min_ball_radius - end_ball_radius(turned), "end.corner");
    }
  }
  note(mer.back().x() - std::min(0.0, mer.front().x()) - c.max_length, "max_length");
  for (size_t i = 1; i < mer.size(); ++i)
    note(std::atan2(std::abs(mer[i].y() - mer[i - 1].y()), mer[i].x() - mer[i - 1].x()) - c.max_cone_angle_rad, "max_cone_angle");
  if (c.convex) {  // a waist: a point lower than the highest points on both sides of it
    std::vector<double> left(mer.size()), right(mer.size());
    for (size_t i = 0; i < mer.size(); ++i) left[i] = std::max(i ? left[i - 1] : 0.0, mer[i].y());
    for (size_t i = mer.size(); i-- > 0;) right[i] = std::max(i + 1 < mer.size() ? right[i + 1] : 0.0, mer[i].y());
    for (size_t i = 1; i + 1 < mer.size(); ++i) note(std::min(left[i - 1], right[i + 1]) - mer[i].y(), "convex");
  }
  return out;
}

ToolRadius tool_from_meridian(const std::vector<Eigen::Vector2d>& zr, int K) {
  if (zr.size() < 2 || !(zr.back().x() > zr.front().x())) throw InputError("tool meridian: at least 2 points with z increasing");
  if (K < 4) throw InputError("tool meridian: at least 4 control points");
  const double z0 = zr.front().x(), L = zr.back().x() - z0;
  // The meridian continued along its end tangents, so that spheres near the ends touch the flank
  // (not the corner where the end face begins): a taper gives an exactly linear d.
  std::vector<Eigen::Vector2d> curve;
  curve.push_back(zr[0] - L * (zr[1] - zr[0]).normalized());
  curve.insert(curve.end(), zr.begin(), zr.end());
  curve.push_back(zr.back() + L * (zr.back() - zr[zr.size() - 2]).normalized());
  const int samples = std::max(8 * K, 200);
  Eigen::MatrixXd d(samples, 1);
  std::vector<double> ss = uniform_parameters(samples);
  for (int j = 0; j < samples; ++j) {
    const Eigen::Vector2d c(z0 + ss[size_t(j)] * L, 0);
    double best = INFINITY;
    for (size_t k = 1; k < curve.size(); ++k) {
      const Eigen::Vector2d u = curve[k] - curve[k - 1];
      const double t = std::clamp((c - curve[k - 1]).dot(u) / u.squaredNorm(), 0.0, 1.0);
      best = std::min(best, (curve[k - 1] + t * u - c).norm());
    }
    d(j, 0) = best;
  }
  const BSpline spline = fit_bspline(d, ss, K, 0.0);
  ToolRadius tool;
  tool.shape = ToolShape::General;
  tool.D.assign(spline.ctrl.data(), spline.ctrl.data() + K);
  return tool;
}

Rails with_length(const Rails& r, double length) {
  Rails out = r;
  const double f = length / r.length;
  out.b.ctrl = r.a.ctrl + f * (r.b.ctrl - r.a.ctrl);  // R'(t, s) = R(t, f s): the same ruled surface
  out.length = length;
  return out;
}

ToolRadius shared_radii(const std::vector<const SurfaceIndex*>& surfaces, const std::vector<Rails>& rails,
                        const FitOptions& o) {
  if (surfaces.size() != rails.size() || rails.empty()) throw InputError("shared tool: one surface per motion");
  const int m = o.samples_t, n = o.samples_s;
  // Mean distance per axis sample s_j over every motion's interior samples, then least squares D.
  std::vector<double> sum(size_t(n), 0.0);
  std::vector<int> count(size_t(n), 0);
  for (size_t p = 0; p < rails.size(); ++p) {
    const auto fps = sample_footpoints(*surfaces[p], rails[p], m, n);
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < n; ++j) {
        const Footpoint& f = fps[size_t(i) * n + j];
        if (f.on_boundary) continue;
        sum[size_t(j)] += f.distance;
        ++count[size_t(j)];
      }
  }
  ToolRadius tool;
  tool.shape = o.shape;
  const int K = shape_parameters(o.shape, o);
  tool.D.assign(size_t(K), 0.0);
  std::vector<Eigen::RowVectorXd> rows;
  std::vector<double> rhs;
  for (int j = 0; j < n; ++j) {
    if (!count[size_t(j)]) continue;
    const double w = std::sqrt(double(count[size_t(j)]));
    const std::vector<double> c = tool.basis(double(j) / (n - 1));
    rows.push_back(w * Eigen::Map<const Eigen::RowVectorXd>(c.data(), K));
    rhs.push_back(w * sum[size_t(j)] / count[size_t(j)]);
  }
  if (rows.size() < size_t(K)) throw InputError("shared tool: the motions are not over the design surface");
  Eigen::MatrixXd C(Eigen::Index(rows.size()), K);
  Eigen::VectorXd b(Eigen::Index(rows.size()));
  for (size_t k = 0; k < rows.size(); ++k) C.row(Eigen::Index(k)) = rows[k], b[Eigen::Index(k)] = rhs[k];
  const Eigen::VectorXd D = C.colPivHouseholderQr().solve(b);
  tool.D.assign(D.data(), D.data() + K);
  return constrained_tool(tool, rails.front().length, o.constraints);
}


namespace {
// One sample of a check surface (CheckSurface): the axis point at (t_i, s) and its radius R plus
// the allowance (cutter: d(s) - tolerance with the radius basis, body: constant + clearance).
struct CheckSample {
  int i = 0;
  double s = 0;
  int j = -1;            // cutter sphere: sample index (radius d_j); -1: a rim point or the body
  double offset = 0;     // R = offset (+ d(s) for a cutter sphere)
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();  // rim points: from the axis point to the rim
  double reach = 0;      // rim and body: their radius (how far the axis is from the sample's surface)
  bool body = false;     // shank or holder
  double grow = 0;       // body: the sag of its spacing, hypot(half gap, r) - r, kept in hand
  double u_lo = 0, u_hi = 0;  // body: its slab along the axis beyond the cutter's end (to the neighbours' midpoints, never across a step)
  double shade = -1;  // body: under a narrower shank, the cutter's radius at its end and the tolerance (body_nearest); else -1
};

// Per body sample: the radius of a sphere at its axis point that encloses the body's slab around it
// (half the gap to each neighbour, the radius linear between samples: the largest of r_k and
// hypot(half gap, radius at its middle) on both sides), and the sag of its spacing,
// hypot(half the larger gap, r_k) - r_k. Two samples at one u are a step in the radius (the holder's
// face above a narrower shank): each stands for its own side of it, so the shank's last sphere is
// not grown to the holder's radius (it was: a phantom 6 mm "intrusion" of every holder over a Ø8
// shank, which trimmed the HECC impeller's patches).
struct BodySphere {
  double reach = 0, sag = 0, u_lo = 0, u_hi = 0;
};
std::vector<BodySphere> body_spheres(const std::vector<Eigen::Vector2d>& body) {
  std::vector<BodySphere> out(body.size());
  for (size_t k = 0; k < body.size(); ++k) {
    double rho = body[k].y(), widest = 0, slab[2] = {body[k].x(), body[k].x()};
    for (const size_t nb : {k - 1, k + 1}) {
      if (nb >= body.size()) continue;  // k - 1 wrapped at k = 0
      const double gap = std::abs(body[nb].x() - body[k].x());
      widest = std::max(widest, gap);
      if (!(gap > 0)) continue;
      rho = std::max(rho, std::hypot(0.5 * gap, 0.5 * (body[k].y() + body[nb].y())));
      slab[nb > k] = 0.5 * (body[k].x() + body[nb].x());
    }
    out[k] = {rho, std::hypot(0.5 * widest, body[k].y()) - body[k].y(), slab[0], slab[1]};
  }
  return out;
}

// The samples of every row. The cutter has flat ends (the canal surface cut off at the tip and at
// the shoulder): its spheres that fit between the ends, and rims of 12 points near both ends; then
// the body (shank, holder) beyond the holder-side end.
std::vector<CheckSample> check_samples(const Rails& r, const ToolRadius& tool, const CheckSurface& c, int m, int n,
                                       int rim_points = 12) {
  std::vector<CheckSample> out;
  bool body_at_b = true;
  if (c.up) body_at_b = mean_axis(r).dot(*c.up) >= 0;
  const double L = std::max(r.length, 1e-12);
  // Rims at the tip and at half and one tip radius above it, and at half and one radius below the
  // shoulder (not at the shoulder itself, where a rim would sit on the edge where the part's top
  // face meets Φ's top boundary; the shank's samples start there).
  std::vector<double> rim_s;
  const double d_a = tool.d(body_at_b ? 0.0 : 1.0), d_b = tool.d(body_at_b ? 1.0 : 0.0);
  if (!c.ball_tip)
    for (const double f : {0.0, 0.5, 1.0}) rim_s.push_back(std::min(f * d_a / L, 0.5));
  for (const double f : {0.5, 1.0}) rim_s.push_back(std::max(1 - f * d_b / L, 0.5));
  if (!body_at_b)
    for (double& x : rim_s) x = 1 - x;
  // A ball end: the sphere tangent to the tip plane and to the side, radius d(0) (1 + sin α) with
  // sin α = d'(z) at the tip (core/tool_end.h), its centre that far above the tip.
  double ball_s = 0, ball_r = 0;
  if (c.ball_tip) {
    const double h = 1e-3, inward = body_at_b ? h : 1 - h;
    const double sin_a = std::clamp((tool.d(inward) - d_a) / (h * L), -0.9, 0.9);
    ball_r = d_a * (1 + sin_a);
    ball_s = std::min(ball_r / L, 0.5);
    if (!body_at_b) ball_s = 1 - ball_s;
  }
  const int kRim = rim_points;
  const std::vector<BodySphere> spheres = body_spheres(c.body);
  for (int i = 0; i < m; ++i) {
    const double t = double(i) / (m - 1);
    for (int j = 0; j < n; ++j) {
      const double sj = double(j) / (n - 1), d = tool.d(sj);
      if (sj * L >= d && (1 - sj) * L >= d) out.push_back({i, sj, j, -c.tolerance, Eigen::Vector3d::Zero(), d});
    }
    const Eigen::Vector3d axis = (r.b.point(t) - r.a.point(t)).normalized();
    const Eigen::Vector3d u_ax = axis.unitOrthogonal(), v_ax = axis.cross(u_ax);
    // Point k of a rim of `kRim` points and radius `radius` around the axis, from the axis point.
    const auto rim_shift = [&](int k, double radius) {
      const double th = 2 * M_PI * k / kRim;
      return Eigen::Vector3d(radius * (std::cos(th) * u_ax + std::sin(th) * v_ax));
    };
    if (c.ball_tip) out.push_back({i, ball_s, -1, ball_r - c.tolerance, Eigen::Vector3d::Zero(), ball_r});
    for (const double sr : rim_s)
      for (int k = 0; k < kRim; ++k) out.push_back({i, sr, -1, -c.tolerance, rim_shift(k, tool.d(sr)), tool.d(sr)});
    // Only under a shank narrower than the cutter's end is the part below that end the cutter's alone
    // (body_nearest); a wider shank's face overhangs the cutter and is held off what lies under it.
    const double shade = !c.body.empty() && c.body[0].y() < d_b ? d_b + c.tolerance : -1.0;
    for (size_t k = 0; k < c.body.size(); ++k) {
      const double u = c.body[k].x(), rho = spheres[k].reach;
      out.push_back({i, body_at_b ? 1 + u / L : -u / L, -1, rho + c.clearance, Eigen::Vector3d::Zero(), rho, true,
                     spheres[k].sag, spheres[k].u_lo, spheres[k].u_hi, shade});
    }
    // The shank's rim at the cutter's end, where the shank is wider than the cutter there: a part
    // point beside it (a flank's edge just short of the cutter's end) is nearer to the rim than any
    // point nearest to the axis, which lie on the flank the cutter touches (on the HECC diffuser the
    // shank passed the vane's lower edge 0.34 mm off, seen only by the collision check, and the
    // program was refused). A narrower shank's rim lies inside the cutter's end face: a part point
    // near it is the cutter's to judge, and counting it for the shank trimmed NASA rotor 37's
    // patches (cutters Ø9.7 over a Ø8 shank) to 77.5% of the blade where they had machined 91.1%.
    if (!c.body.empty() && c.body[0].y() > d_b) {
      const double u = c.body[0].x(), rs = c.body[0].y();
      for (int k = 0; k < kRim; ++k)  // a wider shank: not shaded (CheckSample::shade -1)
        out.push_back({i, body_at_b ? 1 + u / L : -u / L, -1, c.clearance, rim_shift(k, rs), 0.0, true, 0.0, u, u});
    }
  }
  return out;
}

// The signed distance of p to the check part (faces out of the material) and its gradient g.
struct CheckDistance {
  double distance = INFINITY;
  Eigen::Vector3d g = Eigen::Vector3d::Zero(), q = Eigen::Vector3d::Zero();
};
// The footpoint f of p on `mesh` as a signed distance (sign: -1 inside) with its gradient.
CheckDistance signed_at(const SurfaceIndex& mesh, const Eigen::Vector3d& p, const Footpoint& f, double sign) {
  CheckDistance out;
  out.q = f.point;
  out.distance = sign * f.distance;
  out.g = f.distance > 1e-12 ? Eigen::Vector3d(sign * (p - f.point) / f.distance) : face_normal(mesh.mesh(), f.face);
  return out;
}

CheckDistance check_distance(const CheckSurface& c, const Eigen::Vector3d& p, const Footpoint& f, const Footpoint* whole) {
  const SurfaceIndex& part = *c.part;
  if (f.face < 0 || !std::isfinite(f.distance)) return {};
  double sign = 1;
  if (c.solid && whole && whole->face >= 0) {
    // Inside is decided by the whole part (closed, with Φ's twin): more than the tolerance inside it;
    // behind a face of the twin, more than the twin's own sag off Φ besides (its coarse chords may
    // stand proud of Φ, which the cutter touches by construction).
    const bool twin = c.solid_twin && size_t(whole->face) < c.solid_twin->size() && (*c.solid_twin)[size_t(whole->face)];
    const double margin = c.tolerance + (twin ? c.twin_sag : 0.0);
    // Inside, the depth is the way out of the whole part, as deep as the point lies behind its nearest
    // face (Φ's twin included): a sample 0.07 mm behind Φ is 0.07 mm in, pushed back out through Φ,
    // not as deep as the far side of the blade or the hub (the part without the twin), which the
    // HECC impeller's Ø6 fits were trimmed for as "cuts" of 4-6 mm and pushed through the blade.
    if ((p - whole->point).dot(c.solid->pseudo_normal(*whole)) < -margin) return signed_at(*c.solid, p, *whole, -1.0);
  } else {
    // The sign is that of the pseudo-normal at the closest point, except at the part's boundary (where a
    // point in front of a hole is outside though the face normal next to its edge may say otherwise).
    sign = !f.on_boundary && (p - f.point).dot(part.pseudo_normal(f)) < 0 ? -1.0 : 1.0;
  }
  return signed_at(part, p, f, sign);
}

// Shank and holder keep their clearance from the whole part, Φ's twin included: only the cutter is
// Φ's to judge (with the fit's tolerance). Above a patch shorter than the flank the shank runs along
// Φ's continuation, which the part without its twin does not hold (rotor 37 with a 50 mm tool: the
// shank 0.3-0.7 mm into the blade it cuts, found only by the collision check). The twin's chords
// stand off Φ by at most its sag, far below any clearance.
CheckDistance body_distance(const SurfaceIndex& solid, const Eigen::Vector3d& p, const Footpoint& f) {
  if (f.face < 0 || !std::isfinite(f.distance)) return {};
  return signed_at(solid, p, f, (p - f.point).dot(solid.pseudo_normal(f)) < 0 ? -1.0 : 1.0);
}

// The point of the body's outline (shank and holder as a solid of revolution: c.body's (u, r) linear
// between samples, closed by a flat face at the far end) nearest to (u, rho) of the axis' half plane,
// with the outward normal there and the signed gap (< 0 inside). `shade` (CheckSample::shade, -1 under
// a shank wider than the cutter's end): a point below the body's start within it is under the cutter's
// end face or inside the cutter, the cutter's alone (infinite gap), as in the collision check
// (body_gap). A point below a wider shank's overhanging face is the shank's: shading it left the only
// candidates of a Ø30 shank's samples infinite, and its fit drifted 2.58 mm into the part.
struct BodyPoint {
  Eigen::Vector2d at = Eigen::Vector2d::Zero(), normal = Eigen::Vector2d::UnitY();
  double gap = INFINITY;
};
BodyPoint body_nearest(const std::vector<Eigen::Vector2d>& body, const Eigen::Vector2d& q, double shade) {
  BodyPoint out;
  if (body.empty() || (q.x() < body.front().x() && q.y() <= shade)) return out;
  // No face at the cutter's end: the cutter is there (a part point just past it, inside the shank's
  // radius, is as deep as its way out through the shank's side, and the cutter's own samples judge it).
  std::vector<Eigen::Vector2d> outline(body.begin(), body.end());
  outline.emplace_back(body.back().x(), 0.0);
  const PolylinePoint near = polyline_nearest(outline, q);
  const double best = near.distance;
  out.at = near.at;
  // Walking the outline up the side from the cutter's end and down the far face, the material is on
  // the right: the outward normal is the direction turned left.
  const Eigen::Vector2d e = outline[near.segment + 1] - outline[near.segment];
  const Eigen::Vector2d seg_normal = e.squaredNorm() > 0 ? Eigen::Vector2d(-e.y(), e.x()).normalized() : Eigen::Vector2d::UnitY();
  // Inside: between the end faces and below the radius there (at a step, the wider side's).
  bool inside = false;
  if (q.x() >= body.front().x() && q.x() <= body.back().x())
    for (size_t k = 0; k + 1 < body.size() && !inside; ++k) {
      const Eigen::Vector2d a = body[k], b = body[k + 1];
      if (q.x() < a.x() || q.x() > b.x()) continue;
      const double r = b.x() > a.x() ? a.y() + (b.y() - a.y()) * (q.x() - a.x()) / (b.x() - a.x()) : std::max(a.y(), b.y());
      inside = q.y() <= r;
    }
  if (body.size() == 1) inside = false;
  out.gap = inside ? -best : best;
  out.normal = best > 1e-12 ? Eigen::Vector2d((inside ? -1.0 : 1.0) * (q - out.at) / best) : seg_normal;
  return out;
}

// The body's end of a body sample's row and the direction along the axis away from the cutter
// (u grows along it).
struct BodyAxis {
  Eigen::Vector3d end, dir;
};
BodyAxis body_axis(const Rails& r, const CheckSample& cs, int m) {
  const double t = double(cs.i) / (m - 1);
  const Eigen::Vector3d a = r.a.point(t), b = r.b.point(t);
  return cs.s >= 0.5 ? BodyAxis{b, (b - a).normalized()} : BodyAxis{a, (a - b).normalized()};
}

// Shank and holder samples whose axis point lies outside the part: judged exactly at the part point
// found for it, against the body's outline (body_nearest) instead of the sphere that encloses the
// body's slab there (at a holder's face that sphere bulges its whole radius below the face, a
// phantom intrusion over the shank). The sample becomes the outline's point: its axis parameter,
// its shift off the axis, the clearance as its offset; its distance the gap along g, the body's
// inward normal there (pushing the body off the part point). The clearance is kept with the sag of
// the samples' spacing in hand (hypot(half gap, r) - r: 0.12 mm for a Ø8 shank sampled every 2 mm):
// a part point between two samples may be nearer the body than the one found, which the collision
// check's finer slabs see (the HECC impeller: a shank 0.005 mm inside its clearance there, after a
// clean trim). Each sample is judged at two part points, the whole part's nearest to its axis point
// and its slab's own (`in_slab`: the slab along the axis, widened by the clearance; face -1: none),
// the nearer to the body counting: a nearer point beside the shank cannot hide a farther one entering
// the holder through its face.
void resolve_body(const Rails& r, const CheckSurface& c, std::vector<CheckSample>& samples, std::vector<CheckDistance>& dist,
                  const std::vector<Footpoint>& in_slab, int m) {
  const double L = std::max(r.length, 1e-12);
  for (size_t k = 0; k < samples.size(); ++k) {
    CheckSample& cs = samples[k];
    CheckDistance& d = dist[k];
    if (!cs.body || !std::isfinite(d.distance) || d.distance < 0) continue;
    const bool at_b = cs.s >= 0.5;
    const auto [end, dir] = body_axis(r, cs, m);
    Eigen::Vector3d radial = dir.unitOrthogonal();
    BodyPoint bp;
    const Eigen::Vector3d found = d.q;
    for (const Eigen::Vector3d* q : {&found, in_slab[k].face >= 0 ? &in_slab[k].point : nullptr}) {
      if (!q) continue;
      const Eigen::Vector3d v = *q - end;
      const double uq = v.dot(dir);
      const Eigen::Vector3d radial_v = v - uq * dir;
      const double rq = radial_v.norm();
      const BodyPoint here = body_nearest(c.body, {uq, rq}, cs.shade);
      if (here.gap >= bp.gap) continue;
      bp = here;
      radial = rq > 1e-12 ? Eigen::Vector3d(radial_v / rq) : dir.unitOrthogonal();
      d.q = *q;
    }
    cs.s = at_b ? 1 + bp.at.x() / L : -bp.at.x() / L;
    cs.shift = bp.at.y() * radial;
    cs.offset = c.clearance + cs.grow;
    d.g = -(bp.normal.x() * dir + bp.normal.y() * radial);
    d.distance = bp.gap;
  }
}

// Footpoints of the check samples of one motion on the part: the cutter's on the part without Φ's
// twin (and on the whole part for the sign), shank and holder on the whole part alone when there is one
// (and resolved to the body's outline, resolve_body, which changes those samples).
std::vector<CheckDistance> check_distances(const Rails& r, const CheckSurface& c, std::vector<CheckSample>& samples,
                                           int m) {
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(samples.size());
  for (const CheckSample& cs : samples) pts.push_back(r.point(double(cs.i) / (m - 1), cs.s) + cs.shift);
  const auto on_part = [&](size_t k) { return !(samples[k].body && c.solid); };
  std::vector<Eigen::Vector3d> part_pts;
  part_pts.reserve(pts.size());
  for (size_t k = 0; k < pts.size(); ++k)
    if (on_part(k)) part_pts.push_back(pts[k]);
  const std::vector<Footpoint> fps = c.part->closest(part_pts);
  std::vector<Footpoint> whole;
  if (c.solid) whole = c.solid->closest(pts);
  std::vector<CheckDistance> out(samples.size());
  for (size_t k = 0, i = 0; k < samples.size(); ++k)
    out[k] = on_part(k) ? check_distance(c, pts[k], fps[i++], c.solid ? &whole[k] : nullptr)
                        : body_distance(*c.solid, pts[k], whole[k]);
  // Body samples outside the part that its nearest point leaves in doubt (within the reach of the
  // ball around the slab): their slab's own nearest part point too.
  std::vector<Footpoint> in_slab(samples.size());
  const SurfaceIndex& body_part = c.solid ? *c.solid : *c.part;
#pragma omp parallel for schedule(dynamic, 64)
  for (size_t k = 0; k < samples.size(); ++k) {
    const CheckSample& cs = samples[k];
    if (!cs.body || !std::isfinite(out[k].distance) || out[k].distance < 0 ||
        out[k].distance >= cs.reach + c.clearance + cs.grow)
      continue;
    const auto [end, dir] = body_axis(r, cs, m);
    const double base = dir.dot(end), widen = c.clearance + cs.grow;
    // The shank's first sample under a narrower shank: its slab not widened below the cutter's end.
    // The part there within the cutter's radius is the cutter's alone (body_nearest's shade), and
    // where a tapered cutter's flank goes on above its end, that flank lies nearest below the end:
    // the sample saw nothing, while the flank just above the end stood inside the shank's clearance
    // (the HECC impeller: a Ø8 shank over a Ø1.7 -> Ø8.66 mm cutter 0.435 mm off the blade, refused
    // by the collision check after detection had judged it clear).
    const double below = cs.shade > 0 && cs.u_lo <= c.body.front().x() ? 0.0 : widen;  // shade > 0: a body is given
    in_slab[k] = body_part.closest_in_slab(pts[k], dir, base + cs.u_lo - below, base + cs.u_hi + widen);
  }
  resolve_body(r, c, samples, out, in_slab, m);
  return out;
}

// The parameter blocks of row `row` of the rails: the 4 control points of a(t) it weighs, then b(t)'s.
std::vector<double*> rail_blocks(const BasisRow& row, std::vector<double>& A, std::vector<double>& B) {
  std::vector<double*> blocks;
  for (int q = 0; q < 4; ++q) blocks.push_back(&A[size_t(3 * (row.first + q))]);
  for (int q = 0; q < 4; ++q) blocks.push_back(&B[size_t(3 * (row.first + q))]);
  return blocks;
}

// The floor's pulls (CheckSurface::floor_reach): per row, the tip's check sample nearest the part (a
// flat end's rim point, or the ball of a ball end); where that part point lies under the tip, the
// tip's lowest point over the part's tangent plane there (the rim point farthest along -g: a flat
// disk meets a plane first at one point of its rim) is pulled to floor_height above it.
void add_floor_pulls(ceres::Problem& problem, const Rails& rails, const ToolRadius& tool, const CheckSurface& c,
                     const std::vector<CheckSample>& samples, const std::vector<CheckDistance>& dist,
                     const std::vector<BasisRow>& rows, std::vector<double>& A, std::vector<double>& B, double w) {
  const int m = int(rows.size());
  const bool body_at_b = !c.up || mean_axis(rails).dot(*c.up) >= 0;
  const double tip_s = body_at_b ? 0.0 : 1.0;
  std::vector<size_t> nearest(size_t(m), samples.size());
  const auto tip_gap = [&](size_t k) { return dist[k].distance - (c.ball_tip ? samples[k].reach : 0.0); };
  for (size_t k = 0; k < samples.size(); ++k) {
    const CheckSample& cs = samples[k];
    // The tip end's rim (not the holder end's), or the ball at the tip.
    const bool tip = c.ball_tip ? cs.shift.squaredNorm() == 0 : cs.shift.squaredNorm() > 0 && cs.s == tip_s;
    if (cs.body || cs.j >= 0 || !tip || !std::isfinite(dist[k].distance)) continue;
    size_t& best = nearest[size_t(cs.i)];
    if (best == samples.size() || tip_gap(k) < tip_gap(best)) best = k;
  }
  const double target = c.floor_height;
  for (int i = 0; i < m; ++i) {
    const size_t k = nearest[size_t(i)];
    if (k == samples.size()) continue;
    const CheckSample& cs = samples[k];
    const double t = double(i) / (m - 1);
    const Eigen::Vector3d a = rails.a.point(t), b = rails.b.point(t);
    const Eigen::Vector3d up = (body_at_b ? Eigen::Vector3d(b - a) : Eigen::Vector3d(a - b)).normalized();
    const Eigen::Vector3d& g = dist[k].g;
    if (!(g.dot(up) > std::cos(M_PI / 4))) continue;
    const double radius = tool.d(tip_s);
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();  // from the axis point to the lowest point (flat end)
    double lift = 0;                                  // the ball's radius above its lowest point
    if (c.ball_tip) {
      lift = cs.reach;
    } else {
      const Eigen::Vector3d across = g - g.dot(up) * up;
      if (across.norm() > 1e-9) shift = -radius * across.normalized();
    }
    const Eigen::Vector3d p = (1 - cs.s) * a + cs.s * b + shift;
    const double height = (p - dist[k].q).dot(g) - lift;
    if (height > target + c.floor_reach * radius) continue;
    const BasisRow& row = rows[size_t(i)];
    problem.AddResidualBlock(new fit_residuals::CheckResidual(row, cs.s, dist[k].q - shift, g, {}, target + lift, w, true),
                             nullptr, rail_blocks(row, A, B));
  }
}
}  // namespace

std::vector<double> cutter_clearances(const CheckSurface& c, const std::vector<Eigen::Vector3d>& points) {
  std::vector<double> out(points.size(), INFINITY);
  if (!c.part || points.empty()) return out;
  const std::vector<Footpoint> fps = c.part->closest(points);
  std::vector<Footpoint> whole;
  if (c.solid) whole = c.solid->closest(points);
  for (size_t k = 0; k < points.size(); ++k)
    out[k] = check_distance(c, points[k], fps[k], c.solid ? &whole[k] : nullptr).distance;
  return out;
}

CheckProfile check_profile(const Rails& rails, const ToolRadius& tool, const CheckSurface& c, int rows, int samples_s,
                           bool enclose, const SurfaceIndex* design, double design_within) {
  CheckProfile out;
  out.intrusion.assign(size_t(rows), -INFINITY);
  out.body.assign(size_t(rows), 0);
  out.at.assign(size_t(rows), Eigen::Vector3d::Zero());
  if (!c.part || rows < 2) return out;
  const double L = std::max(rails.length, 1e-12);
  // `enclose`: spheres along the cutter close enough that the dip of their union, h^2 / (8 d), stays
  // below a quarter of the tolerance (as the collision check samples it), the smallest radius
  // counted from a tenth of the largest; rims with enough points that the circle sags between two of
  // them by under a quarter of the tolerance.
  int rim_points = 12;
  double rim_sag = 0;
  if (enclose) {
    double dmax = 0;
    for (int j = 0; j <= 64; ++j) dmax = std::max(dmax, tool.d(j / 64.0));
    double dmin = dmax;
    for (int j = 0; j <= 64; ++j) dmin = std::min(dmin, std::max(tool.d(j / 64.0), 0.1 * dmax));
    const double h = std::sqrt(2 * dmin * std::max(c.tolerance, 1e-9));
    samples_s = std::clamp(int(std::ceil(L / h)) + 1, samples_s, 512);
    const double step = std::acos(std::clamp(1 - 0.25 * std::max(c.tolerance, 1e-9) / std::max(dmax, 1e-12), -1.0, 1.0));
    rim_points = std::clamp(int(std::ceil(M_PI / std::max(step, 1e-9))), 12, 720);
    rim_sag = dmax * (1 - std::cos(M_PI / rim_points));
  }
  std::vector<CheckSample> samples = check_samples(rails, tool, c, rows, samples_s, rim_points);
  if (enclose) {
    for (CheckSample& cs : samples)
      if (!cs.body && cs.j < 0 && cs.shift.squaredNorm() > 0) cs.offset += rim_sag;
    // Each sphere of the cutter grown to enclose its slab of the solid (half the spacing on both
    // sides), so a part point between two samples cannot come nearer than the samples say (the
    // body's balls enclose theirs always, body_spheres, in the fit too).
    const double half_s = 0.5 / (samples_s - 1);
    for (CheckSample& cs : samples) {
      if (cs.j >= 0) {
        const double d = tool.d(cs.s);
        const double slab = std::max({d, tool.d(std::max(0.0, cs.s - half_s)), tool.d(std::min(1.0, cs.s + half_s))});
        cs.offset += std::hypot(half_s * L, slab) - d;
      }
    }
  }
  const std::vector<CheckDistance> dist = check_distances(rails, c, samples, rows);
  for (size_t k = 0; k < samples.size(); ++k) {
    const CheckSample& cs = samples[k];
    const double R = cs.offset + (cs.j >= 0 ? tool.d(cs.s) : 0.0);
    const double v = R - dist[k].distance;
    // A cutter hit where the part's coarse faces meet the hole Φ's twin left is Φ's (HECC impeller:
    // a hub face 0.008 mm off Φ's foot trimmed a patch by 5% of its motion the collision check
    // passes).
    if (v > 0 && design && !cs.body && left_to_design(*design, dist[k].q, design_within)) continue;
    if (v > out.intrusion[size_t(cs.i)]) {
      out.intrusion[size_t(cs.i)] = v;
      out.body[size_t(cs.i)] = cs.body;
      out.at[size_t(cs.i)] = dist[k].q;
    }
  }
  return out;
}

Eigen::Vector3d holder_up(const Rails& rails, const ToolRadius& tool, const CheckSurface& c, int rows,
                          const Eigen::Vector3d& fallback) {
  const Eigen::Vector3d axis = mean_axis(rails);
  if (!c.part || c.body.empty() || rows < 2) return axis.dot(fallback) >= 0 ? axis : Eigen::Vector3d(-axis);
  // (rows whose shank or holder enters the part, summed intrusion) with the holder at b, then at a.
  std::array<std::pair<int, double>, 2> score{};
  for (int e = 0; e < 2; ++e) {
    CheckSurface ce = c;
    ce.up = e == 0 ? axis : Eigen::Vector3d(-axis);
    std::vector<CheckSample> samples = check_samples(rails, tool, ce, rows, 2);
    samples.erase(std::remove_if(samples.begin(), samples.end(), [](const CheckSample& s) { return !s.body; }),
                  samples.end());
    const std::vector<CheckDistance> dist = check_distances(rails, ce, samples, rows);
    std::vector<double> worst(size_t(rows), 0.0);
    for (size_t k = 0; k < samples.size(); ++k)
      worst[size_t(samples[k].i)] = std::max(worst[size_t(samples[k].i)], samples[k].offset - dist[k].distance);
    for (double w : worst)
      if (w > 0) ++score[size_t(e)].first, score[size_t(e)].second += w;
  }
  if (score[0] == score[1]) return axis.dot(fallback) >= 0 ? axis : Eigen::Vector3d(-axis);
  return score[0] < score[1] ? axis : Eigen::Vector3d(-axis);
}

namespace {
// A fit in progress: one or several motions (patches) sharing one tool.
struct Joint {
  std::vector<Rails> rails;
  ToolRadius tool;
  FitStatus status = FitStatus::IterationLimit;
  std::string message;
  std::vector<double> objective;  // F_motion after each round
  int iterations = 0;
};

// Outer rounds (footpoints recomputed, then one solve) of eq. (12) summed over every motion of `st`
// with one set of radii; radii_free: d are unknowns (eq. 12) or held. `anchor_tool`: see w_anchor.
Joint fit_rounds(const std::vector<const SurfaceIndex*>& surfaces, Joint st, const FitOptions& o, bool radii_free,
                 const ToolRadius& anchor_tool, int max_rounds) {
  const int m = o.samples_t, n = o.samples_s, Nc = o.rail_control_points;
  const size_t P = st.rails.size();
  std::vector<BasisRow> rows(static_cast<size_t>(m));
  for (int i = 0; i < m; ++i) rows[size_t(i)] = bspline_basis(Nc, double(i) / (m - 1));
  std::vector<std::vector<double>> tool_basis(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) tool_basis[size_t(j)] = st.tool.basis(double(j) / (n - 1));
  const int K = int(st.tool.D.size());
  const bool constrained = radii_free && o.constraints.active();
  st.status = FitStatus::IterationLimit;
  std::vector<RoundMeasures> history;  // of the motion before each round
  for (int iter = 0; iter < max_rounds; ++iter) {
    // Footpoints of every patch's samples; their distance errors are eq. (13) of the motion so far.
    std::vector<std::vector<Footpoint>> footpoints(P);
    RoundMeasures before;
    int counted = 0;
    for (size_t p = 0; p < P; ++p) {
      footpoints[p] = sample_footpoints(*surfaces[p], st.rails[p], m, n);
      const ErrorStats e = footpoint_error(footpoints[p], st.tool, m, n, false);
      before.eps = std::max(before.eps, e.max);
      before.mean_error += e.mean * e.samples;
      counted += e.samples;
    }
    if (counted > 0) before.mean_error /= counted;

    // Unknowns: control points of every a(t), b(t) and the radius parameters D.
    std::vector<std::vector<double>> As(P, std::vector<double>(size_t(3 * Nc))), Bs = As;
    for (size_t p = 0; p < P; ++p)
      for (int k = 0; k < Nc; ++k)
        for (int c = 0; c < 3; ++c) {
          As[p][size_t(3 * k + c)] = st.rails[p].a.ctrl(k, c);
          Bs[p][size_t(3 * k + c)] = st.rails[p].b.ctrl(k, c);
        }
    std::vector<double> D = st.tool.D;

    struct SamplePlane {
      size_t p;
      int i, j;
      Eigen::Vector3d n;
    };
    std::vector<SamplePlane> planes;  // the samples in this round's objective
    ceres::Problem::Options po;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    const double w_plane = std::sqrt(o.w_plane / (double(m) * n)), w_point = std::sqrt(o.w_point / (double(m) * n));
    ceres::CauchyLoss robust(w_plane * o.robust_scale);
    ceres::LossFunction* loss = o.robust_scale > 0 ? &robust : nullptr;
    for (size_t p = 0; p < P; ++p) {
      std::vector<double>& A = As[p];
      std::vector<double>& B = Bs[p];
      const Rails& rails = st.rails[p];
      const double L = rails.length;
      const std::vector<Footpoint>& fps = footpoints[p];
      for (int i = 0; i < m; ++i) {
        const BasisRow& row = rows[size_t(i)];
        std::vector<double*> blocks = rail_blocks(row, A, B);
        blocks.push_back(D.data());
        for (int j = 0; j < n; ++j) {
          const Footpoint& f = fps[size_t(i) * n + j];
          const double s = double(j) / (n - 1);
          const auto plane = sample_plane(rails.point(double(i) / (m - 1), s), f);
          if (!plane) continue;  // the axis point is beyond Φ's boundary: no data there
          const Eigen::Vector3d nrm = *plane;
          planes.push_back({p, i, j, nrm});
          problem.AddResidualBlock(new SampleResidual(row, s, f.point, nrm, tool_basis[size_t(j)], w_plane, w_point),
                                   loss, blocks);
        }
        // F_rigid, eq. (9), soft.
        if (o.w_rigid > 0)
          problem.AddResidualBlock(new RigidResidual(row, L, std::sqrt(o.w_rigid / m)), nullptr,
                                   std::vector<double*>(blocks.begin(), blocks.begin() + 8));
      }
      // F_fair, eq. (11): second differences of a(t_i) and b(t_i).
      if (o.w_fair > 0) {
        const double w = std::sqrt(o.w_fair / m);
        for (int i = 1; i + 1 < m; ++i) {
          Eigen::RowVectorXd coef = Eigen::RowVectorXd::Zero(Nc);
          for (int di = -1; di <= 1; ++di) {
            const BasisRow& r = rows[size_t(i + di)];
            for (int k = 0; k < 4; ++k) coef[r.first + k] += (di == 0 ? -2.0 : 1.0) * r.w[k];
          }
          for (std::vector<double>* X : {&A, &B}) {
            std::vector<Eigen::MatrixXd> J;
            std::vector<double*> blocks;
            Eigen::Vector3d start = Eigen::Vector3d::Zero();  // second difference at the start of this round
            for (int k = 0; k < Nc; ++k)
              if (coef[k] != 0) {
                J.push_back(w * coef[k] * Eigen::Matrix3d::Identity());
                blocks.push_back(&(*X)[size_t(3 * k)]);
                start += w * coef[k] * Eigen::Map<const Eigen::Vector3d>(&(*X)[size_t(3 * k)]);
              }
            const Eigen::Vector3d rhs = o.fair_update ? start : Eigen::Vector3d::Zero();
            problem.AddResidualBlock(new LinearResidual(std::move(J), rhs), nullptr, blocks);
          }
        }
      }
      // Check surfaces: one-sided penalties keep the cutter and its body out of the part.
      if (o.check.part) {
        std::vector<CheckSample> samples = check_samples(rails, st.tool, o.check, m, n);
        const std::vector<CheckDistance> dist = check_distances(rails, o.check, samples, m);
        const double w = w_plane * o.check.weight;
        for (size_t k = 0; k < samples.size(); ++k) {
          const CheckSample& cs = samples[k];
          const double R = cs.offset + (cs.j >= 0 ? st.tool.d(cs.s) : 0.0);
          // Beyond the band: clear. An axis point inside the part (or nearly): the motion is not
          // near a clear one there, the linearisation means nothing, and trimming decides instead.
          const double reach = cs.j >= 0 ? st.tool.d(cs.s) : cs.reach;
          if (!(dist[k].distance < R + o.check.band) || !(R - dist[k].distance < o.check.depth_limit * reach)) continue;
          const BasisRow& row = rows[size_t(cs.i)];
          std::vector<double*> blocks = rail_blocks(row, A, B);
          std::vector<double> c;
          if (cs.j >= 0) {
            c = tool_basis[size_t(cs.j)];
            blocks.push_back(D.data());
          }
          problem.AddResidualBlock(new fit_residuals::CheckResidual(row, cs.s, dist[k].q - cs.shift, dist[k].g, std::move(c),
                                                                    cs.offset, w),
                                   nullptr, blocks);
        }
        if (o.check.floor_reach > 0) add_floor_pulls(problem, rails, st.tool, o.check, samples, dist, rows, A, B,
                                                     w_plane * std::sqrt(double(n)) * o.check.floor_weight);
      }
    }  // patches
    // Anchor of the tool radii (not in the paper): on nearly developable surfaces a shift of the axis
    // along the surface normal with an equal change of every d_j leaves the envelope almost unchanged,
    // so the radii are barely determined by Φ. A weak pull to the initial meridian fixes that mode.
    if (radii_free && o.w_anchor > 0) {
      const double w = std::sqrt(o.w_anchor / n);
      Eigen::MatrixXd C(n, K);
      Eigen::VectorXd target(n);
      for (int j = 0; j < n; ++j) {
        for (int k = 0; k < K; ++k) C(j, k) = w * tool_basis[size_t(j)][size_t(k)];
        target[j] = w * anchor_tool.d(double(j) / (n - 1));
      }
      problem.AddResidualBlock(new LinearResidual({C}, target), nullptr, D.data());
    }
    // Tool constraints (Sec. 4.6) as one-sided penalties on the radii; the projection after the
    // joint rounds makes them exact.
    if (constrained) {
      const ConstraintRows c = constraint_rows(st.tool, st.rails.front().length, o.constraints);
      if (c.h.size() > 0) problem.AddResidualBlock(new fit_residuals::HingeResidual(c.G, c.h, o.w_constraint), nullptr, D.data());
    }
    // No sample of the motion over Φ (it has left the surface): nothing to fit it to, and with the
    // radii held Ceres would abort on their absent block. The last motion is kept and reported.
    if (planes.empty()) {
      st.status = FitStatus::SolverFailed;
      st.message = "no sample of the motion lies over the design surface";
      break;
    }
    if (!radii_free) problem.SetParameterBlockConstant(D.data());
    ceres::Solver::Options so;
    // Each sample touches 8 of the 2 x rail_control_points control points and the radii: J^T J is
    // sparse (about a third of the dense matrix is non-zero at 16 control points), and the sparse
    // normal Cholesky is faster than the dense one (bench/fit_bench).
    so.linear_solver_type = ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ||
                                    ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::EIGEN_SPARSE)
                                ? ceres::SPARSE_NORMAL_CHOLESKY
                                : ceres::DENSE_NORMAL_CHOLESKY;
    so.max_num_iterations = o.solver_iterations;
    // One thread: Ceres sums cost and gradient per thread in a varying order, so the result would
    // depend on the thread count in the last digits (issue 12). The closest points, most of a fit's
    // time, run on OpenMP threads around the solve.
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    // NO_CONVERGENCE only means the round used its solver_iterations; FAILURE (or a cost that is
    // not finite) is a result, not an exception: the last good motion is kept and reported.
    if (fit_residuals::solve_failed(summary)) {
      st.status = FitStatus::SolverFailed;
      st.message = "Ceres: " + summary.message;
      break;
    }

    // How far the envelope moved in this round: the largest displacement along a sample's plane
    // normal of the axis point minus the change of its radius (unit frame). A drift of the axis
    // along the normal with an equal change of the radii (nearly free on developable surfaces,
    // see w_anchor) does not move the envelope and does not count.
    std::vector<Rails> next = st.rails;
    for (size_t p = 0; p < P; ++p)
      for (int k = 0; k < Nc; ++k)
        for (int c = 0; c < 3; ++c) {
          next[p].a.ctrl(k, c) = As[p][size_t(3 * k + c)];
          next[p].b.ctrl(k, c) = Bs[p][size_t(3 * k + c)];
        }
    ToolRadius next_tool = st.tool;
    next_tool.D = D;
    double moved = 0;
    for (const SamplePlane& sp : planes) {
      const double t = double(sp.i) / (m - 1), s = double(sp.j) / (n - 1);
      moved = std::max(moved, std::abs((next[sp.p].point(t, s) - st.rails[sp.p].point(t, s)).dot(sp.n) -
                                       (next_tool.d(s) - st.tool.d(s))));
    }
    // The solve starts from the motion so far at fresh footpoints: its initial cost is that motion's
    // F_motion (with fair_update, F_fair of the update is 0 there).
    before.objective = 2 * summary.initial_cost;
    history.push_back(before);
    st.rails = std::move(next);
    st.tool = std::move(next_tool);
    const double objective = 2 * summary.final_cost;  // F_motion, eq. (12)
    st.objective.push_back(objective);
    st.iterations += 1;
    if (o.on_iteration) o.on_iteration(st.iterations, objective);
    // Converged when the motion and the radii stop moving, or when a round cannot lower its own
    // objective (the footpoints, and which samples lie beyond Φ, change between solves, so
    // progress is judged within a solve).
    if (objective <= 0 || moved <= o.motion_tolerance ||
        summary.initial_cost - summary.final_cost < o.stall * summary.initial_cost) {
      st.status = FitStatus::Converged;
      break;
    }
    // Or when the rounds have stopped lowering F_motion at fresh footpoints, ε and the mean error:
    // each solve may still lower its own objective, by sliding the motion along a nearly free
    // direction (FitOptions::plateau).
    if (fit_plateaued(history, o.plateau, o.plateau_rounds)) {
      st.status = FitStatus::Converged;
      break;
    }
  }
  return st;
}
}  // namespace

FitResult optimize_motion(const SurfaceIndex& surface, const Rails& initial, const FitOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError(err);
  const int Nc = o.rail_control_points;
  FitResult result;
  result.rails = initial;
  if (initial.a.size() != Nc || initial.b.size() != Nc)
    throw InputError("optimize_motion: rails must have rail_control_points control points");
  const bool constrained = !o.fixed_tool && o.constraints.active();
  // A tool no longer than max_length: the axis is shortened at the b end before the fit (the
  // meridian's own overhang beyond the axis is corrected after it, below).
  result.tool = o.fixed_tool ? *o.fixed_tool : initial_tool(surface, initial, o);
  result.eps_ini = sample_error(surface, initial, result.tool, o);
  if (constrained && result.rails.length > o.constraints.max_length) {
    result.rails = with_length(result.rails, o.constraints.max_length);
    result.tool = initial_tool(surface, result.rails, o);
  }
  if (constrained) result.tool = constrained_tool(result.tool, result.rails.length, o.constraints);
  const ToolRadius anchor_tool = result.tool;

  const std::vector<const SurfaceIndex*> surfaces{&surface};
  const auto rounds = [&](bool radii_free, int max_rounds) {
    Joint st{{result.rails}, result.tool, result.status, {}, std::move(result.objective), result.iterations};
    st = fit_rounds(surfaces, std::move(st), o, radii_free, anchor_tool, max_rounds);
    result.rails = std::move(st.rails.front());
    result.tool = std::move(st.tool);
    result.status = st.status;
    result.message = std::move(st.message);
    result.objective = std::move(st.objective);
    result.iterations = st.iterations;
  };
  rounds(!o.fixed_tool, o.max_iterations);
  // Constrained tools: the radii projected onto the constraints, then the motion fitted to that
  // admissible tool with the radii held; a meridian that overhangs max_length shortens the axis.
  for (int pass = 0; constrained && result.status != FitStatus::SolverFailed && pass < 4; ++pass) {
    result.tool = constrained_tool(result.tool, result.rails.length, o.constraints);
    rounds(false, o.max_iterations);
    const std::vector<Eigen::Vector2d> mer = meridian(result.tool, result.rails.length, 121);
    const double excess = mer.back().x() - std::min(0.0, mer.front().x()) - o.constraints.max_length;
    if (!(excess > 0)) break;
    result.rails = with_length(result.rails, result.rails.length - excess * 1.01 - 1e-9);
  }
  result.converged = result.status == FitStatus::Converged;
  result.eps_opt = sample_error(surface, result.rails, result.tool, o);
  return result;
}

std::vector<FitResult> fit_shared_tool(const std::vector<const SurfaceIndex*>& surfaces, std::vector<FitResult> fits,
                                       double length, const FitOptions& o) {
  if (surfaces.size() != fits.size() || fits.empty()) throw InputError("shared tool: one surface per patch");
  if (auto err = o.validate(); !err.empty()) throw InputError(err);
  Joint st;
  for (FitResult& f : fits) st.rails.push_back(with_length(f.rails, length));
  // Start: the meridian update over all patches (mean distances), then eq. (12) summed over the
  // patches with their rails and the one set of radii as unknowns, as optimize_motion does for one.
  st.tool = o.fixed_tool ? *o.fixed_tool : shared_radii(surfaces, st.rails, o);
  const ToolRadius anchor = st.tool;
  const bool constrained = !o.fixed_tool && o.constraints.active();
  st = fit_rounds(surfaces, std::move(st), o, !o.fixed_tool, anchor, o.max_iterations);
  if (constrained && st.status != FitStatus::SolverFailed) {
    st.tool = constrained_tool(st.tool, length, o.constraints);
    st = fit_rounds(surfaces, std::move(st), o, false, anchor, o.max_iterations);
  }
  for (size_t p = 0; p < fits.size(); ++p) {
    FitResult& f = fits[p];
    f.rails = st.rails[p];
    f.tool = st.tool;
    f.iterations += st.iterations;
    f.objective = st.objective;
    f.status = st.status;
    f.converged = st.status == FitStatus::Converged;
    f.message = st.message;
    f.eps_opt = sample_error(*surfaces[p], f.rails, f.tool, o);
  }
  return fits;
}

}  // namespace flankcam
