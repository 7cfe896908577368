#include "core/blade.h"

#include <Eigen/Geometry>

#include <cmath>

#include "core/errors.h"

namespace flankcam {

std::string BladeOptions::validate() const {
  if (!(span > 0)) return "span: must be > 0 mm";
  if (!(chord_hub > 0) || !(chord_tip > 0)) return "chord: must be > 0 mm";
  if (!(thickness > 0 && thickness < 0.4)) return "thickness: must be in (0, 0.4) of the chord";
  if (!(camber >= 0 && camber < 0.1)) return "camber: must be in [0, 0.1) of the chord";
  if (!(camber_position > 0 && camber_position < 1)) return "camber_position: must be in (0, 1)";
  if (!(chord_from >= 0 && chord_from < chord_to && chord_to <= 1)) return "chord range: need 0 <= from < to <= 1";
  if (grid_chord < 2 || grid_span < 2) return "grid: at least 2 x 2";
  return {};
}

Eigen::Vector3d Blade::point(double u, double v) const {
  const BladeOptions& o = options;
  // NACA 4-digit upper surface at x = u (fraction of the chord), cosine spacing left to the caller.
  const double x = u, m = o.camber, p = o.camber_position, t = o.thickness;
  const double yt = 5 * t * (0.2969 * std::sqrt(x) - 0.1260 * x - 0.3516 * x * x + 0.2843 * x * x * x - 0.1015 * x * x * x * x);
  const double yc = x < p ? m / (p * p) * (2 * p * x - x * x) : m / ((1 - p) * (1 - p)) * ((1 - 2 * p) + 2 * p * x - x * x);
  const double dyc = x < p ? 2 * m / (p * p) * (p - x) : 2 * m / ((1 - p) * (1 - p)) * (p - x);
  const double th = std::atan(dyc);
  const double chord = o.chord_hub + v * (o.chord_tip - o.chord_hub);
  // Section in its plane, stacked at the quarter chord, then twisted about +Z.
  const Eigen::Vector2d q = chord * Eigen::Vector2d(x - yt * std::sin(th) - 0.25, yc + yt * std::cos(th));
  const double twist = v * o.twist_deg * M_PI / 180;
  const Eigen::Vector2d r = Eigen::Rotation2Dd(twist) * q;
  return {r.x(), r.y(), v * o.span};
}

Eigen::Vector3d Blade::normal(double u, double v) const {
  const double h = 1e-5;
  const Eigen::Vector3d du = point(std::min(1.0, u + h), v) - point(std::max(0.0, u - h), v);
  const Eigen::Vector3d dv = point(u, std::min(1.0, v + h)) - point(u, std::max(0.0, v - h));
  // Chord runs along +x and span along +z: du x dv points to -y; the suction side faces +y.
  return dv.cross(du).normalized();
}

Blade make_blade(const BladeOptions& o) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("blade: " + why);
  Blade b;
  b.options = o;
  const int nu = o.grid_chord, nv = o.grid_span;
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const double u = o.chord_from + (o.chord_to - o.chord_from) * i / (nu - 1), v = double(j) / (nv - 1);
      b.mesh.vertices.push_back(b.point(u, v));
    }
  // Counter-clockwise seen from the outward (+y, suction) side.
  for (int j = 0; j + 1 < nv; ++j)
    for (int i = 0; i + 1 < nu; ++i) {
      const int a = j * nu + i;
      b.mesh.faces.push_back({a, a + nu, a + 1});
      b.mesh.faces.push_back({a + 1, a + nu, a + nu + 1});
    }
  return b;
}

std::vector<std::vector<std::array<double, 6>>> blade_lines(const Blade& b, int patches, int per_patch, double offset,
                                                           double overhang) {
  if (patches < 1 || per_patch < 2) throw InputError("blade lines: at least one patch and two lines per patch");
  std::vector<std::vector<std::array<double, 6>>> out(static_cast<size_t>(patches), std::vector<std::array<double, 6>>{});
  const BladeOptions& o = b.options;
  for (int k = 0; k < patches; ++k)
    for (int i = 0; i < per_patch; ++i) {
      // Keep clear of the patch borders by a quarter of a line spacing.
      const double f = (i + 0.25 + 0.5 * i / (per_patch - 1)) / per_patch;
      const double u = o.chord_from + (o.chord_to - o.chord_from) * (k + f) / patches;
      const Eigen::Vector3d a = b.point(u, 0) + offset * b.normal(u, 0), c = b.point(u, 1) + offset * b.normal(u, 1);
      const Eigen::Vector3d dir = (c - a).normalized();
      const Eigen::Vector3d p = a - overhang * dir, q = c + overhang * dir;
      out[size_t(k)].push_back({p.x(), p.y(), p.z(), q.x(), q.y(), q.z()});
    }
  return out;
}

}  // namespace flankcam
