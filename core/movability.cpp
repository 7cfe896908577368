#include "core/movability.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <tuple>

#include "core/errors.h"

namespace flankcam {

namespace {

constexpr double kSlidePrice = 1e-3;  // relative to trace(A)

// Orthonormal n1, n2 spanning the plane normal to the unit vector e (deterministic choice).
std::pair<Eigen::Vector3d, Eigen::Vector3d> normal_plane(const Eigen::Vector3d& e) {
  Eigen::Index k;
  e.cwiseAbs().minCoeff(&k);
  const Eigen::Vector3d n1 = e.cross(Eigen::Vector3d::Unit(k)).normalized();
  return {n1, e.cross(n1)};
}

}  // namespace

double smooth_distance(const SurfaceIndex& surface, const Footpoint& f, const Eigen::Vector3d& p) {
  const auto& corner = surface.mesh().faces[size_t(f.face)];
  const auto& V = surface.mesh().vertices;
  const auto& N = surface.normals();
  double bulge = 0;  // of the smooth surface over the facet, along the normal
  for (int i = 0; i < 3; ++i)
    for (int j = i + 1; j < 3; ++j) {
      const size_t vi = size_t(corner[size_t(i)]), vj = size_t(corner[size_t(j)]);
      bulge -= 4 * f.barycentric[i] * f.barycentric[j] * (V[vj] - V[vi]).dot(N[vi] - N[vj]) / 8;
    }
  return (p - f.point).dot(f.normal) - bulge;
}

std::string MovabilityOptions::validate() const {
  if (samples < 5) return "samples: at least 5 points on a line";
  if (!(jump_ratio > 1)) return "jump_ratio: must be greater than 1";
  return {};
}

std::string ExplorationOptions::validate() const {
  if (auto e = movability.validate(); !e.empty()) return e;
  if (candidates < 1) return "candidates: at least 1";
  if (rounds < 1) return "rounds: at least 1";
  if (!(radius > 0)) return "radius: must be positive";
  if (!(shrink > 0 && shrink < 1)) return "shrink: must be between 0 and 1";
  if (!(good_enough >= 0)) return "good_enough: must be >= 0";
  return {};
}

std::string OrientationOptions::validate() const {
  if (auto e = movability.validate(); !e.empty()) return e;
  if (!(first_step_deg > 0 && first_step_deg <= 45)) return "first_step_deg: must be in (0, 45]";
  if (!(last_step_deg > 0 && last_step_deg <= first_step_deg)) return "last_step_deg: must be in (0, first_step_deg]";
  if (max_evaluations < 0) return "max_evaluations: must be >= 0";
  if (!(min_inside_share >= 0 && min_inside_share <= 1)) return "min_inside_share: must be in [0, 1]";
  return {};
}

std::string PropagationOptions::validate() const {
  if (auto e = movability.validate(); !e.empty()) return e;
  if (!(step > 0 && step < 0.1)) return "step: must be in (0, 0.1) of the diagonal";
  if (!(max_movability > 0)) return "max_movability: must be positive";
  if (!(max_boundary_share > 0 && max_boundary_share <= 1)) return "max_boundary_share: must be in (0, 1]";
  if (max_steps < 1) return "max_steps: at least 1";
  return {};
}

const char* to_string(PropagationStop s) {
  switch (s) {
    case PropagationStop::Boundary: return "boundary";
    case PropagationStop::Movability: return "movability";
    case PropagationStop::NotMovable: return "not movable";
    case PropagationStop::MaxSteps: return "max steps";
  }
  return "?";
}

Movability line_movability(const SurfaceIndex& surface, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                           const MovabilityOptions& o) {
  Movability out;
  const int n = o.samples;
  const Eigen::Vector3d axis = b - a;
  const double L = axis.norm();
  if (!(L > 0)) return out;
  const Eigen::Vector3d e = axis / L;
  const auto [n1, n2] = normal_plane(e);

  std::vector<Eigen::Vector3d> points(n);
  for (int i = 0; i < n; ++i) {
    const double s = double(i) / (n - 1);
    points[i] = (1 - s) * a + s * b;
  }
  out.footpoints = surface.closest(points);

  // A = (1/n) sum g_i g_i^T with <v_i, r_i> = g_i . x, x = (v_a, λ1, λ2), eq. (5).
  Eigen::Matrix<double, 5, 5> A = Eigen::Matrix<double, 5, 5>::Zero();
  int prev = -1;
  bool branches = false;
  for (int i = 0; i < n; ++i) {
    const Footpoint& f = out.footpoints[i];
    if (f.on_boundary) {
      ++out.boundary_samples;
      continue;
    }
    if (prev >= 0) {
      // Remark 1: a jump of the footpoints along the line means a second branch of the characteristic.
      const double line_step = (points[i] - points[prev]).norm();
      if ((f.point - out.footpoints[prev].point).norm() > o.jump_ratio * line_step) branches = true;
    }
    prev = i;
    Eigen::Vector3d r = points[i] - f.point;
    const double len = r.norm();
    r = len > 1e-12 ? Eigen::Vector3d(r / len) : f.normal;
    const double s = double(i) / (n - 1);
    Eigen::Matrix<double, 5, 1> g;
    g << r, s * r.dot(n1), s * r.dot(n2);
    A += g * g.transpose();
    ++out.used_samples;
  }
  if (out.used_samples < 5) return out;
  A /= out.used_samples;

  // A line sliding along itself is the same line, so the normalisation (6) applies to the part of
  // v_m normal to the line (otherwise every cylinder would be perfectly "movable" along its axis):
  // y = (α, β, γ, λ1, λ2) with v_m = α n1 + β n2 + γ e, v_a = v_m - (λ1 n1 + λ2 n2)/2, α² + β² = 1.
  Eigen::Matrix<double, 5, 5> T = Eigen::Matrix<double, 5, 5>::Zero();
  T.block<3, 1>(0, 0) = n1;
  T.block<3, 1>(0, 1) = n2;
  T.block<3, 1>(0, 2) = e;
  T.block<3, 1>(0, 3) = -0.5 * n1;
  T.block<3, 1>(0, 4) = -0.5 * n2;
  T(3, 3) = 1;
  T(4, 4) = 1;
  const Eigen::Matrix<double, 5, 5> Ay = T.transpose() * A * T;
  const Eigen::Matrix2d P = Ay.topLeftCorner<2, 2>();
  const Eigen::Matrix<double, 2, 3> Q = Ay.topRightCorner<2, 3>();
  Eigen::Matrix3d R = Ay.bottomRightCorner<3, 3>();
  // On nearly developable surfaces a tilted line can also glide along the rulings, almost purely by
  // sliding along itself (F ~ 0 as well); a small price on the axial velocity γ makes the sweep
  // across the surface, the motion a flank cut needs, the minimiser.
  R(0, 0) += kSlidePrice * A.trace();
  // Pseudo-inverse of R: components that do not change F (e.g. sliding of a cylinder) stay 0.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> er(R);
  Eigen::Matrix3d R_pinv = Eigen::Matrix3d::Zero();
  // Components whose curvature is below 1e-6 of A's scale are treated as free: inverting them
  // would turn rounding noise of the footpoints into huge axial or rotational velocities.
  const double r_tol = 1e-6 * std::max(A.trace(), 1e-300);
  for (int k = 0; k < 3; ++k)
    if (er.eigenvalues()[k] > r_tol)
      R_pinv += er.eigenvectors().col(k) * er.eigenvectors().col(k).transpose() / er.eigenvalues()[k];
  const Eigen::Matrix2d S = P - Q * R_pinv * Q.transpose();  // Schur complement
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(S);
  const Eigen::Vector2d ab = es.eigenvectors().col(0);  // smallest eigenvalue first
  const Eigen::Vector3d rest = -R_pinv * Q.transpose() * ab;  // γ, λ1, λ2
  out.F = std::max(0.0, es.eigenvalues()[0]);
  const Eigen::Vector3d v_m = ab[0] * n1 + ab[1] * n2 + rest[0] * e;
  const Eigen::Vector3d dv = rest[1] * n1 + rest[2] * n2;
  out.v_a = v_m - 0.5 * dv;
  out.v_b = out.v_a + dv;
  out.movable = !branches;
  return out;
}

ExploredLine explore_line(const SurfaceIndex& surface, const Eigen::Vector3d& a0, const Eigen::Vector3d& b0,
                          const ExplorationOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError("exploration." + err);
  ExploredLine best;
  best.a = a0;
  best.b = b0;
  best.movability = line_movability(surface, a0, b0, o.movability);
  best.F_start = best.movability.F;
  best.lines_evaluated = 1;
  const auto acceptable = [&](const Movability& m) { return m.movable && m.used_samples * 2 >= o.movability.samples; };
  double best_F = acceptable(best.movability) ? best.movability.F : INFINITY;
  double radius = o.radius;
  for (int round = 0; round < o.rounds && !(best_F <= o.good_enough); ++round, radius *= o.shrink) {
    // Named copies: a lambda may not capture structured bindings in C++17 (clang rejects it).
    const auto plane = normal_plane((best.b - best.a).normalized());
    const Eigen::Vector3d n1 = plane.first, n2 = plane.second;
    std::mt19937 rng(o.seed + 7919u * unsigned(round));
    std::uniform_real_distribution<double> u(0, 1);
    const auto disc = [&]() {  // uniform in the disc of this round's radius; the first candidate is no change
      const double r = radius * std::sqrt(u(rng)), phi = 2 * M_PI * u(rng);
      return Eigen::Vector3d(r * std::cos(phi) * n1 + r * std::sin(phi) * n2);
    };
    std::vector<Eigen::Vector3d> da(o.candidates, Eigen::Vector3d::Zero()), db(o.candidates, Eigen::Vector3d::Zero());
    for (int k = 1; k < o.candidates; ++k) da[k] = disc();
    for (int k = 1; k < o.candidates; ++k) db[k] = disc();
    const int count = o.candidates * o.candidates;
    std::vector<Movability> results(count);
#pragma omp parallel for schedule(dynamic, 8)
    for (int k = 0; k < count; ++k)
      results[k] = line_movability(surface, best.a + da[k / o.candidates], best.b + db[k % o.candidates], o.movability);
    best.lines_evaluated += count;
    int pick = -1;
    // A candidate must lower F_l clearly (10%, and above rounding): where F_l is already near zero
    // many lines are equally movable and the user's line should not wander among them.
    for (int k = 0; k < count; ++k)
      if (acceptable(results[k]) && results[k].F < 0.9 * best_F - 1e-12) {
        best_F = results[k].F;
        pick = k;
      }
    if (pick >= 0) {
      best.a += da[pick / o.candidates];
      best.b += db[pick % o.candidates];
      best.movability = std::move(results[pick]);
    }
  }
  return best;
}

OrientedLine orient_line(const SurfaceIndex& surface, const Eigen::Vector3d& a0, const Eigen::Vector3d& b0,
                         const Eigen::Vector3d& pivot, const OrientationOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError("orientation." + err);
  OrientedLine out;
  out.a = a0;
  out.b = b0;
  out.movability = line_movability(surface, a0, b0, o.movability);
  out.lines_evaluated = 1;
  const double L = (b0 - a0).norm();
  if (!(L > 0)) return out;
  const Eigen::Vector3d e0 = (b0 - a0) / L;
  // The line as pivot + u e with u in [u0, u1]; turning it keeps u0, u1.
  const double u0 = (a0 - pivot).dot(e0), u1 = (b0 - pivot).dot(e0);
  const Eigen::Vector3d base = pivot + (a0 - pivot - u0 * e0);  // pivot moved onto the line
  // Named, not a structured binding: C++17 lambdas cannot capture bindings (clang rejects it).
  const std::pair<Eigen::Vector3d, Eigen::Vector3d> plane = normal_plane(e0);
  const Eigen::Vector3d& n1 = plane.first;
  const Eigen::Vector3d& n2 = plane.second;
  const auto acceptable = [&](const Movability& m) {
    return m.movable && m.used_samples >= o.min_inside_share * o.movability.samples;
  };
  const auto line_at = [&](const Eigen::Vector2d& x) {
    const Eigen::Vector3d e = (e0 + std::tan(x[0]) * n1 + std::tan(x[1]) * n2).normalized();
    return std::make_pair(Eigen::Vector3d(base + u0 * e), Eigen::Vector3d(base + u1 * e));
  };
  Eigen::Vector2d best = Eigen::Vector2d::Zero();
  double best_F = acceptable(out.movability) ? out.movability.F : std::numeric_limits<double>::infinity();
  double h = o.first_step_deg * M_PI / 180;
  const double h_min = o.last_step_deg * M_PI / 180;
  while (h >= h_min * (1 - 1e-9) && out.lines_evaluated <= o.max_evaluations) {
    Eigen::Vector2d step_best = best;
    double step_F = best_F;
    Movability step_m;
    for (int i = 0; i < 2; ++i)
      for (int sign : {-1, 1}) {
        Eigen::Vector2d x = best;
        x[i] += sign * h;
        const auto [a, b] = line_at(x);
        Movability m = line_movability(surface, a, b, o.movability);
        ++out.lines_evaluated;
        if (acceptable(m) && m.F < step_F) step_F = m.F, step_best = x, step_m = std::move(m);
      }
    if (step_F < best_F) {
      best = step_best;
      best_F = step_F;
      std::tie(out.a, out.b) = line_at(best);
      out.movability = std::move(step_m);
    } else {
      h *= 0.5;
    }
  }
  return out;
}

namespace {

struct Walk {
  std::vector<Eigen::Vector3d> a, b;  // positions after the start
  std::vector<double> F;
  PropagationStop stop = PropagationStop::MaxSteps;
};

// Walks from (a, b), whose movability is `start`, along the best tangential field in
// direction +1 or -1, keeping the length.
Walk walk(const SurfaceIndex& surface, Eigen::Vector3d a, Eigen::Vector3d b, Movability m, int direction,
          const PropagationOptions& o) {
  Walk w;
  const double L = (b - a).norm();
  Eigen::Vector3d previous_vm = Eigen::Vector3d::Zero();
  double slid = 0;  // how far the line has slid along itself (unit frame): the tool moved with it
  // The tool's radii at the start: the distance of each sample to Φ (NaN beyond Φ), eq. (8)'s d_j.
  const int n0 = int(m.footpoints.size());
  std::vector<double> d0(size_t(n0), std::numeric_limits<double>::quiet_NaN());
  for (int i = 0; i < n0; ++i)
    if (!m.footpoints[size_t(i)].on_boundary) d0[size_t(i)] = m.footpoints[size_t(i)].distance;
  const auto radius_at = [&](double u) {  // u: tool coordinate in [0, 1] from a at the start
    if (n0 < 2 || !(u >= 0 && u <= 1)) return std::numeric_limits<double>::quiet_NaN();
    const double x = u * (n0 - 1);
    const int i = std::min(int(x), n0 - 2);
    const double f = x - i;
    return (1 - f) * d0[size_t(i)] + f * d0[size_t(i + 1)];
  };
  for (int step = 0; step < o.max_steps; ++step) {
    if (step > 0) {
      m = line_movability(surface, a, b, o.movability);
      // Keep the rigid line centred on Φ: where the motion carries it towards an edge of Φ across
      // its sweep (one end's footpoints on the boundary, the other end's not), slide it back along
      // itself. Sliding is not a motion of the line, but without it a curved sweep leaves Φ over
      // one end and stopped at the boundary half way (helix envelopes: half the surface).
      const int n = int(m.footpoints.size());  // none for a line that is not finite
      int lead = 0, trail = 0;
      while (lead < n && m.footpoints[size_t(lead)].on_boundary) ++lead;
      while (trail < n && m.footpoints[size_t(n - 1 - trail)].on_boundary) ++trail;
      if (lead < n && lead != trail && (lead == 0 || trail == 0)) {
        // At most half a step per step: drift towards an s-edge is slow, while crossing a t-edge
        // obliquely must not push the line along itself.
        const double want = 0.5 * (lead - trail) * L / (n - 1);
        const double slide = std::clamp(want, -0.5 * o.step, 0.5 * o.step);
        const Eigen::Vector3d shift = slide * (b - a) / L;
        a += shift;
        b += shift;
        slid += slide;
        m = line_movability(surface, a, b, o.movability);
      }
      if (m.boundary_samples > o.max_boundary_share * o.movability.samples) {
        w.stop = PropagationStop::Boundary;
        return w;
      }
    }
    if (!m.movable || m.used_samples < 5) {
      w.stop = PropagationStop::NotMovable;
      return w;
    }
    if (step > 0) {
      if (m.F > o.max_movability) {
        w.stop = PropagationStop::Movability;
        return w;
      }
      w.a.push_back(a);
      w.b.push_back(b);
      w.F.push_back(m.F);
    }
    const Eigen::Vector3d e = (b - a).normalized();
    // Sliding along itself does not move the line but does move the tool: accumulated over the
    // steps it carried one end off Φ, so curved motions stopped early at the boundary and the
    // tool's reach shrank at that end. The common axial part of the field is removed.
    const double slide = 0.5 * (m.v_a + m.v_b).dot(e);
    Eigen::Vector3d va = m.v_a - slide * e, vb = m.v_b - slide * e;
    const Eigen::Vector3d vm = 0.5 * (va + vb);  // normal part: |vm| = 1
    // The eigenvector's sign is arbitrary: keep moving the way we went.
    const double sign = step == 0 ? double(direction) : (vm.dot(previous_vm) >= 0 ? 1.0 : -1.0);
    va *= sign;
    vb *= sign;
    previous_vm = sign * vm;
    a += o.step * va;
    b += o.step * vb;
    Eigen::Vector3d mid = 0.5 * (a + b), e_new = (b - a).normalized();
    a = mid - 0.5 * L * e_new;  // keep the length L (rigid line)
    b = mid + 0.5 * L * e_new;
    if (o.keep_radii) {
      // Corrector: the step along the best field is first order, and on surfaces where several
      // fields are nearly as movable it wanders off the axis. A rigid tool keeps each axis point's
      // distance to Φ (eq. 8), so one damped Gauss-Newton step moves the line back to the start's
      // distances: rows (1 - s) u^T, s u^T for the endpoints, u the unit direction from the footpoint.
      const int n = o.movability.samples;
      std::vector<Eigen::Vector3d> pts(static_cast<size_t>(n));
      for (int i = 0; i < n; ++i) {
        const double si = double(i) / (n - 1);
        pts[size_t(i)] = (1 - si) * a + si * b;
      }
      const std::vector<Footpoint> f = surface.closest(pts);
      Eigen::Matrix<double, 6, 6> JtJ = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> Jtr = Eigen::Matrix<double, 6, 1>::Zero();
      int rows = 0;
      for (int i = 0; i < n; ++i) {
        const Footpoint& fp = f[size_t(i)];
        const double si = double(i) / (n - 1);
        const double want = radius_at(si + slid / L);
        if (fp.on_boundary || !std::isfinite(want) || !(fp.distance > 1e-12)) continue;
        const Eigen::Vector3d u = (pts[size_t(i)] - fp.point) / fp.distance;
        Eigen::Matrix<double, 6, 1> J;
        J << (1 - si) * u, si * u;
        JtJ += J * J.transpose();
        Jtr += J * (fp.distance - want);
        ++rows;
      }
      if (rows >= 5) {
        JtJ += 1e-3 * (JtJ.trace() / 6) * Eigen::Matrix<double, 6, 6>::Identity();
        const Eigen::Matrix<double, 6, 1> x = -JtJ.ldlt().solve(Jtr);
        // Never more than a step: the corrector must not jump to another sheet.
        const double scale = std::min(1.0, o.step / std::max(x.head<3>().norm(), x.tail<3>().norm()));
        if (std::isfinite(scale)) {
          a += scale * x.head<3>();
          b += scale * x.tail<3>();
          mid = 0.5 * (a + b);
          e_new = (b - a).normalized();
          a = mid - 0.5 * L * e_new;
          b = mid + 0.5 * L * e_new;
        }
      }
    }
  }
  return w;
}

}  // namespace

LineTrajectory propagate_line(const SurfaceIndex& surface, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                              const PropagationOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError("propagation." + err);
  const Movability m0 = line_movability(surface, a, b, o.movability);
  const Walk back = walk(surface, a, b, m0, -1, o), fwd = walk(surface, a, b, m0, +1, o);
  LineTrajectory out;
  out.stop_backward = back.stop;
  out.stop_forward = fwd.stop;
  out.a.assign(back.a.rbegin(), back.a.rend());
  out.b.assign(back.b.rbegin(), back.b.rend());
  out.F.assign(back.F.rbegin(), back.F.rend());
  out.a.push_back(a);
  out.b.push_back(b);
  out.F.push_back(m0.F);
  out.a.insert(out.a.end(), fwd.a.begin(), fwd.a.end());
  out.b.insert(out.b.end(), fwd.b.begin(), fwd.b.end());
  out.F.insert(out.F.end(), fwd.F.begin(), fwd.F.end());
  return out;
}

}  // namespace flankcam
