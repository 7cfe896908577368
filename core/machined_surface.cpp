#include "core/machined_surface.h"

#include <cmath>
#include <limits>

#include "core/errors.h"

namespace flankcam {

std::string MachinedSurfaceOptions::validate() const {
  if (grid_s < 2 || grid_t < 2) return "envelope grid: at least 2 x 2";
  return {};
}

int tool_side(const SurfaceIndex& design, const Rails& rails) {
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i <= 20; ++i)
    for (int j = 0; j <= 4; ++j) pts.push_back(rails.point(i / 20.0, j / 4.0));
  const auto fps = design.closest(pts);
  double vote = 0;
  for (size_t k = 0; k < pts.size(); ++k)
    if (!fps[k].on_boundary) vote += (pts[k] - fps[k].point).dot(fps[k].normal) >= 0 ? 1 : -1;
  return vote >= 0 ? 1 : -1;
}

MachinedSurface machined_surface(const SurfaceIndex& design, const Rails& rails, const ToolRadius& tool,
                                 const MachinedSurfaceOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError(err);
  MachinedSurface out;
  const LineMotion motion = to_motion(rails);
  const RadiusProfile profile = tool.profile();
  // The sheet facing Φ: the one whose mid point lies closer to Φ.
  {
    const double t = 0.5, s = 0.5;
    const Eigen::Vector3d a = motion.a(t), b = motion.b(t);
    double best = std::numeric_limits<double>::infinity();
    for (int sheet : {1, -1}) {
      const EnvelopePoint p = envelope_point((1 - s) * a + s * b, b - a, (1 - s) * motion.da(t) + s * motion.db(t),
                                             profile.d(s), profile.d_s(s), sheet);
      if (!p.valid) continue;
      const double d = design.closest(p.point).distance;
      if (d < best) {
        best = d;
        out.sheet = sheet;
      }
    }
  }
  out.omega = envelope_grid(motion, profile, o.grid_s, o.grid_t, out.sheet);
  out.tool_side = tool_side(design, rails);
  const double nan = std::numeric_limits<double>::quiet_NaN();

  const auto on_design = design.closest(out.omega.mesh.vertices);
  out.omega_deviation.assign(out.omega.mesh.vertices.size(), nan);
  for (size_t k = 0; k < on_design.size(); ++k) {
    const Footpoint& f = on_design[k];
    if (!out.omega.valid[k] || f.on_boundary) continue;
    out.omega_deviation[k] = (out.omega.mesh.vertices[k] - f.point).dot(out.tool_side * f.normal);
  }
  out.design_deviation.assign(design.mesh().vertices.size(), nan);
  out.design_row.assign(design.mesh().vertices.size(), -1);
  if (out.omega.mesh.faces.empty()) return out;
  const SurfaceIndex omega_index(out.omega.mesh);
  const auto on_omega = omega_index.closest(design.mesh().vertices);
  const auto& normals = design.normals();
  for (size_t v = 0; v < on_omega.size(); ++v) {
    if (on_omega[v].on_boundary) continue;  // Ω does not reach this vertex
    out.design_deviation[v] = (on_omega[v].point - design.mesh().vertices[v]).dot(out.tool_side * normals[v]);
    out.design_row[v] = out.omega.mesh.faces[size_t(on_omega[v].face)][0] / out.omega.n_s;
  }
  return out;
}

double coverage(const TriMesh& design, const std::vector<double>& dev, double tolerance) {
  std::vector<double> area(design.vertices.size(), 0.0);
  for (int f = 0; f < int(design.faces.size()); ++f)
    for (int v : design.faces[f]) area[size_t(v)] += face_area(design, f) / 3;
  double total = 0, within = 0;
  for (size_t v = 0; v < area.size(); ++v) {
    total += area[v];
    if (std::isfinite(dev[v]) && std::abs(dev[v]) <= tolerance) within += area[v];
  }
  return total > 0 ? within / total : 0.0;
}

}  // namespace flankcam
