#include "core/envelope.h"

#include <Eigen/Geometry>
#include <cmath>

#include "core/errors.h"

namespace flankcam {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector3d central_difference(const std::function<Eigen::Vector3d(double)>& f, double t) {
  constexpr double h = 1e-4;  // error O(h^4): ~1e-14 relative for the analytic motions
  return (-f(t + 2 * h) + 8 * f(t + h) - 8 * f(t - h) + f(t - 2 * h)) / (12 * h);
}

BSpline spline_of(std::initializer_list<double> values) {
  BSpline s;
  s.ctrl.resize(Eigen::Index(values.size()), 1);
  Eigen::Index i = 0;
  for (double v : values) s.ctrl(i++, 0) = v;
  return s;
}

Eigen::Vector3d rotate(const Eigen::Vector3d& v, const Eigen::Vector3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()) * v;
}

}  // namespace

LineMotion motion_from_positions(std::function<Eigen::Vector3d(double)> a, std::function<Eigen::Vector3d(double)> b) {
  LineMotion m;
  m.a = a;
  m.b = b;
  m.da = [a](double t) { return central_difference(a, t); };
  m.db = [b](double t) { return central_difference(b, t); };
  return m;
}

LineMotion motion_from_rails(const BSpline& a, const BSpline& b) {
  LineMotion m;
  m.a = [a](double t) { return a.point(t, 0); };
  m.b = [b](double t) { return b.point(t, 0); };
  m.da = [a](double t) { return a.point(t, 1); };
  m.db = [b](double t) { return b.point(t, 1); };
  return m;
}

RadiusProfile cylinder_profile(double r) { return {spline_of({r, r, r, r})}; }
RadiusProfile cone_profile(double r0, double r1) {
  return {spline_of({r0, r0 + (r1 - r0) / 3, r0 + 2 * (r1 - r0) / 3, r1})};
}
RadiusProfile barrel_profile(double r_end, double bulge) {
  // Degree elevation of the quadratic Bezier (r, r + 2 bulge, r).
  return {spline_of({r_end, r_end + 4 * bulge / 3, r_end + 4 * bulge / 3, r_end})};
}
RadiusProfile spline_profile(const std::vector<double>& ctrl) {
  if (ctrl.size() < 4) throw InputError("spline profile: at least 4 control values are needed");
  RadiusProfile p;
  p.radius.ctrl = Eigen::Map<const Eigen::VectorXd>(ctrl.data(), Eigen::Index(ctrl.size()));
  return p;
}

EnvelopePoint envelope_point(const Eigen::Vector3d& c, const Eigen::Vector3d& c_s, const Eigen::Vector3d& c_t,
                             double d, double d_s, int sheet) {
  EnvelopePoint out;
  const double len = c_s.norm();
  if (len <= 0) return out;
  const Eigen::Vector3d e1 = c_s / len;
  const Eigen::Vector3d w_perp = c_t - c_t.dot(e1) * e1;
  const double w_len = w_perp.norm();
  if (w_len <= 1e-12 * std::max(1.0, c_t.norm())) return out;  // point moves along the axis: no characteristic
  const Eigen::Vector3d e2 = w_perp / w_len;
  const Eigen::Vector3d e3 = e1.cross(e2);
  const double x = -d_s / len;                   // n·c_s = -d'(s)
  const double y = -x * c_t.dot(e1) / w_len;     // n·c_t = 0
  const double zz = 1.0 - x * x - y * y;
  if (zz < 0) return out;
  out.normal = x * e1 + y * e2 + (sheet >= 0 ? 1.0 : -1.0) * std::sqrt(zz) * e3;
  out.point = c + d * out.normal;
  out.valid = true;
  return out;
}

EnvelopeGrid envelope_grid(const LineMotion& m, const RadiusProfile& profile, int n_s, int n_t, int sheet, double t0,
                           double t1, double s0) {
  if (n_s < 2 || n_t < 2) throw InputError("envelope grid: at least 2 x 2 samples");
  EnvelopeGrid g;
  g.n_s = n_s;
  g.n_t = n_t;
  g.mesh.vertices.resize(size_t(n_s) * n_t);
  g.valid.assign(size_t(n_s) * n_t, 0);
  std::vector<Eigen::Vector3d> normals(size_t(n_s) * n_t);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n_t; ++i) {
    const double t = t0 + (t1 - t0) * i / (n_t - 1);
    const Eigen::Vector3d a = m.a(t), b = m.b(t), da = m.da(t), db = m.db(t);
    for (int j = 0; j < n_s; ++j) {
      const double s = s0 + (1 - s0) * j / (n_s - 1);
      const EnvelopePoint p = envelope_point((1 - s) * a + s * b, b - a, (1 - s) * da + s * db, profile.d(s),
                                             profile.d_s(s), sheet);
      const size_t k = size_t(i) * n_s + j;
      g.mesh.vertices[k] = p.point;
      normals[k] = p.normal;
      g.valid[k] = p.valid;
    }
  }
  for (char v : g.valid) g.invalid_points += !v;
  // Two triangles per grid cell.
  for (int i = 0; i + 1 < n_t; ++i)
    for (int j = 0; j + 1 < n_s; ++j) {
      const int v00 = i * n_s + j, v01 = v00 + 1, v10 = v00 + n_s, v11 = v10 + 1;
      if (!(g.valid[v00] && g.valid[v01] && g.valid[v10] && g.valid[v11])) continue;
      g.mesh.faces.push_back({v00, v10, v11});
      g.mesh.faces.push_back({v00, v11, v01});
    }
  // The first face decides the orientation for all (consistent grid); then count folds.
  if (!g.mesh.faces.empty()) {
    const auto& P = g.mesh.vertices;
    const auto& f0 = g.mesh.faces[0];
    const bool flip = (P[f0[1]] - P[f0[0]]).cross(P[f0[2]] - P[f0[0]]).dot(normals[f0[0]]) > 0;
    g.folded.assign(g.mesh.faces.size(), 0);
    for (size_t k = 0; k < g.mesh.faces.size(); ++k) {
      auto& f = g.mesh.faces[k];
      if (flip) std::swap(f[1], f[2]);
      const Eigen::Vector3d fn = (P[f[1]] - P[f[0]]).cross(P[f[2]] - P[f[0]]);
      if (fn.dot(normals[f[0]] + normals[f[1]] + normals[f[2]]) >= 0) ++g.folded_triangles, g.folded[k] = 1;
    }
  }
  return g;
}

void validate(const AnalyticMotionOptions& o) {
  if (o.kind != "twist" && o.kind != "arc" && o.kind != "helix" && o.kind != "s-curve")
    throw InputError("motion: unknown kind '" + o.kind + "' (twist, arc, helix, s-curve)");
  if (!(o.length > 0) || !std::isfinite(o.length)) throw InputError("length: must be a positive number of mm");
  if (!(o.travel > 0) || !std::isfinite(o.travel)) throw InputError("travel: must be a positive number of mm");
  if (!std::isfinite(o.twist_deg) || std::abs(o.twist_deg) > 90)
    throw InputError("twist: must be between -90 and 90 degrees");
}

LineMotion analytic_motion(const AnalyticMotionOptions& o) {
  validate(o);
  const double L = o.length, T = o.travel, twist = o.twist_deg * kPi / 180;
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Z = Eigen::Vector3d::UnitZ();
  std::function<Eigen::Vector3d(double)> a, e;
  if (o.kind == "twist") {
    // Straight translation along X while the axis turns about X at a varying rate (a twisted
    // flank; a constant rate would be a screw motion, whose envelope admits a family of tools).
    a = [T](double t) { return Eigen::Vector3d(T * t, 0, 0); };
    e = [twist, X, Z](double t) { return rotate(Z, X, twist * (t * t * (3 - 2 * t) - 0.5)); };
  } else if (o.kind == "arc") {
    // Circular path of radius T in the XY plane, axis leaning outwards by 10 degrees + twist.
    const double sweep = 60 * kPi / 180, lean = 10 * kPi / 180;
    a = [T, sweep](double t) {
      const double phi = sweep * (t - 0.5);
      return Eigen::Vector3d(T * std::cos(phi), T * std::sin(phi), 0);
    };
    e = [sweep, lean, twist, Z](double t) {
      const double phi = sweep * (t - 0.5);
      const Eigen::Vector3d radial(std::cos(phi), std::sin(phi), 0), tangent(-std::sin(phi), std::cos(phi), 0);
      return rotate(rotate(Z, tangent, lean), radial, twist * (t - 0.5));
    };
  } else if (o.kind == "helix") {
    // Quarter turn of a helix of radius 2T/3 rising T/3, axis tilted 15 degrees towards the path.
    const double R = 2 * T / 3, H = T / 3, turn = kPi / 2, tilt = 15 * kPi / 180;
    a = [R, H, turn](double t) {
      const double phi = turn * t;
      return Eigen::Vector3d(R * std::cos(phi), R * std::sin(phi), H * t);
    };
    e = [turn, tilt, twist, Z](double t) {
      const double phi = turn * t;
      const Eigen::Vector3d radial(std::cos(phi), std::sin(phi), 0);
      return rotate(rotate(Z, radial, tilt), radial.cross(Z), 0.5 * twist * (t - 0.5));
    };
  } else {
    // S-shaped path in the XY plane, the axis rocking about the path direction.
    const double amp = T / 10;
    a = [T, amp](double t) { return Eigen::Vector3d(T * t, amp * std::sin(2 * kPi * t), 0); };
    e = [T, amp, twist, Z](double t) {
      const Eigen::Vector3d dir = Eigen::Vector3d(T, amp * 2 * kPi * std::cos(2 * kPi * t), 0).normalized();
      return rotate(Z, dir, 0.5 * twist * std::sin(kPi * t));
    };
  }
  return motion_from_positions(a, [a, e, L](double t) { return Eigen::Vector3d(a(t) + L * e(t)); });
}

}  // namespace flankcam
