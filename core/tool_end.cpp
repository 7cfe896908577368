#include "core/tool_end.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/errors.h"

namespace flankcam {

const char* to_string(EndKind k) {
  switch (k) {
    case EndKind::Ball: return "ball";
    case EndKind::Corner: return "corner";
    default: return "flat";
  }
}

namespace {

// The side offset inwards by R, where it crosses the height z0 + R: the corner circle's centre
// radius rc, the tangent point on the side, its outward normal and its s.
struct Crossing {
  bool found = false;
  double rc = 0, s = 0;
  Eigen::Vector2d point{0, 0}, normal{0, 1};
};

Eigen::Vector2d outward_normal(const std::vector<Eigen::Vector2d>& p, size_t k) {
  const size_t a = k == 0 ? 0 : k - 1, b = std::min(p.size() - 1, k + 1);
  const Eigen::Vector2d t = (p[b] - p[a]).normalized();
  return {-t.y(), t.x()};  // (z, r): the tangent turned by +90 deg points away from the axis
}

Crossing crossing(const std::vector<Eigen::Vector2d>& side, double R) {
  Crossing c;
  const double target = side.front().x() + R;
  Eigen::Vector2d prev_o(0, 0), prev_n(0, 1);
  for (size_t k = 0; k < side.size(); ++k) {
    const Eigen::Vector2d n = outward_normal(side, k), o = side[k] - R * n;
    if (k > 0 && o.x() >= target && prev_o.x() < target) {
      const double lam = (target - prev_o.x()) / (o.x() - prev_o.x());
      c.found = true;
      c.rc = prev_o.y() + lam * (o.y() - prev_o.y());
      c.point = side[k - 1] + lam * (side[k] - side[k - 1]);
      c.normal = (prev_n + lam * (n - prev_n)).normalized();
      c.s = (double(k - 1) + lam) / double(side.size() - 1);
      return c;
    }
    prev_o = o, prev_n = n;
  }
  return c;
}

void check_side(const std::vector<Eigen::Vector2d>& side) {
  if (side.size() < 2) throw InputError("tool end: the tool's meridian needs at least two points");
  for (size_t k = 1; k < side.size(); ++k)
    if (!(side[k].x() > side[k - 1].x())) throw InputError("tool end: the tool's meridian must have increasing z");
}

}  // namespace

double ball_radius(const std::vector<Eigen::Vector2d>& side) {
  check_side(side);
  const double r0 = side.front().y();
  if (!(r0 > 0)) throw InputError("tool end: ball: the tool has no tip radius");
  // rc(R) falls from r0 (R -> 0) through 0 at the ball radius; bracket it, then bisect.
  double lo = 0, hi = r0;
  for (int k = 0; k < 60; ++k) {
    const Crossing c = crossing(side, hi);
    if (!c.found) throw InputError("tool.end: ball: the tool is too short for a ball end");
    if (c.rc <= 0) break;
    lo = hi, hi *= 1.25;
  }
  for (int k = 0; k < 80; ++k) {
    const double mid = 0.5 * (lo + hi);
    const Crossing c = crossing(side, mid);
    if (c.found && c.rc > 0) lo = mid; else hi = mid;
  }
  return 0.5 * (lo + hi);
}

EndProfile end_profile(const std::vector<Eigen::Vector2d>& side, const ToolEnd& end, int arc_points) {
  check_side(side);
  EndProfile out;
  out.tip_z = side.front().x();
  if (end.kind == EndKind::Flat) {
    out.profile = side;
    return out;
  }
  if (arc_points < 2) throw InputError("tool end: at least 2 arc points");
  double R = end.corner_radius;
  if (end.kind == EndKind::Ball) {
    R = ball_radius(side);
  } else {
    const double mm = end.unit_mm;
    if (!(R > 0) || !std::isfinite(R)) throw InputError(fmt::format("tool.end.corner: the radius must be > 0 mm, got {:g}", R * mm));
    const double ball = ball_radius(side);
    if (R > ball * (1 + 1e-9))
      throw InputError(fmt::format("tool.end.corner: {:.4f} mm is larger than the tool's ball radius {:.4f} mm at the tip "
                                   "(tip radius {:.4f} mm; use end: ball or a smaller corner)",
                                   R * mm, ball * mm, side.front().y() * mm));
  }
  Crossing c = crossing(side, R);
  if (!c.found) throw InputError(fmt::format("tool.end: the tool is too short for a corner radius of {:g} mm", R * end.unit_mm));
  if (end.kind == EndKind::Ball || c.rc < 0) c.rc = 0;
  out.radius = R;
  out.centre = {out.tip_z + R, c.rc};
  out.side_s = c.s;
  const double psi_t = std::atan2(c.normal.y(), -c.normal.x());  // from the tip face's direction to the side's normal
  for (int i = 0; i < arc_points; ++i) {
    const double psi = psi_t * i / arc_points;
    out.profile.push_back(out.centre + R * Eigen::Vector2d(-std::cos(psi), std::sin(psi)));
  }
  out.profile.front() = {out.tip_z, c.rc};  // exactly on the tip plane
  out.end_points = arc_points;
  out.profile.push_back(c.point);
  const double eps = 1e-12 * (1 + std::abs(c.point.x()));
  for (const Eigen::Vector2d& p : side)
    if (p.x() > c.point.x() + eps) out.profile.push_back(p);
  return out;
}

double profile_radius(const std::vector<Eigen::Vector2d>& p, double z) {
  if (z <= p.front().x()) return p.front().y();
  if (z >= p.back().x()) return p.back().y();
  const auto it = std::upper_bound(p.begin(), p.end(), z, [](double v, const Eigen::Vector2d& q) { return v < q.x(); });
  const Eigen::Vector2d &a = *(it - 1), &b = *it;
  return a.y() + (b.y() - a.y()) * (z - a.x()) / (b.x() - a.x());
}

PolylinePoint polyline_nearest(const std::vector<Eigen::Vector2d>& line, const Eigen::Vector2d& q) {
  PolylinePoint out;
  for (size_t k = 0; k + 1 < line.size(); ++k) {
    const Eigen::Vector2d a = line[k], e = line[k + 1] - a;
    const double len2 = e.squaredNorm();
    if (!(len2 > 0)) continue;
    const Eigen::Vector2d x = a + std::clamp((q - a).dot(e) / len2, 0.0, 1.0) * e;
    const double d = (q - x).norm();
    if (d < out.distance) out = {k, x, d};
  }
  if (!std::isfinite(out.distance) && !line.empty()) out = {0, line[0], (q - line[0]).norm()};
  return out;
}

EndDistance end_distance(const EndProfile& e, double z, double rho) {
  const std::vector<Eigen::Vector2d>& p = e.profile;
  const double z0 = e.tip_z;
  // Unsigned distance to the end's curve (the tip face, then the arc), and whether its nearest
  // point is the curve's top end.
  double d;
  bool top;
  if (e.end_points == 0) {
    const double r0 = p.front().y();
    d = std::hypot(z - z0, rho - std::clamp(rho, 0.0, r0));
    top = rho > r0 && z > z0;  // beside the tool above the tip plane: the side's business
  } else {
    const double rc = e.centre.y(), R = e.radius;
    const double d_face = std::hypot(z - z0, rho - std::clamp(rho, 0.0, rc));
    const Eigen::Vector2d q(z, rho), v = q - e.centre;
    const Eigen::Vector2d tangent = p[size_t(e.end_points)];
    const double psi_t = std::atan2((tangent - e.centre).y(), -(tangent - e.centre).x());
    const double psi = std::atan2(v.y(), -v.x());
    double d_arc;
    bool arc_top = false;
    if (psi >= 0 && psi <= psi_t) {
      d_arc = std::abs(v.norm() - R);
    } else {
      const double d_bottom = (q - Eigen::Vector2d(z0, rc)).norm(), d_top = (q - tangent).norm();
      d_arc = std::min(d_bottom, d_top);
      arc_top = d_top < d_bottom;
    }
    d = std::min(d_face, d_arc);
    top = d_arc < d_face && arc_top;
  }
  EndDistance out;
  const bool inside = z > z0 && z < p.back().x() && rho < profile_radius(p, z);
  if (!inside) {
    out.distance = d;
    out.reached = !top;
    return out;
  }
  // Inside: as deep as the shorter way out, through the end or radially through the side.
  const double radial = profile_radius(p, z) - rho;
  out.distance = -std::min(d, radial);
  out.reached = d <= radial && !top;
  return out;
}

EndProfile checked_end_profile(const std::vector<Eigen::Vector2d>& cutter, const std::vector<Eigen::Vector2d>& side,
                               const ToolEnd& end) {
  if (end.kind == EndKind::Flat) return end_profile(cutter, end);
  EndProfile e = end_profile(side, end);
  // The side meridian ends d(1) sin a short of the axis end where the tool widens towards its holder
  // (beyond it where it narrows).
  const double top = cutter.back().x();
  while (e.profile.size() > size_t(e.end_points) + 2 && e.profile.back().x() >= top) e.profile.pop_back();
  for (const Eigen::Vector2d& q : cutter)
    if (q.x() > e.profile.back().x()) e.profile.push_back(q);
  return e;
}

}  // namespace flankcam
