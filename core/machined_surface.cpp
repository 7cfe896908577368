#include "core/machined_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "core/errors.h"

namespace flankcam {

std::string MachinedSurfaceOptions::validate() const {
  if (grid_s < 2 || grid_t < 2) return "envelope grid: at least 2 x 2";
  if (end && end->kind == EndKind::Corner && !(end->corner_radius > 0)) return "tool end: the corner radius must be > 0";
  return {};
}

namespace {

// The tool's end swept along the motion: per Φ vertex the signed distance to the swept end (> 0
// outside the tool: material left), minimised over the poses t_i and refined by golden section
// between the neighbours of the best one. A vertex whose best pose is the first or the last, or
// whose nearest point of the end is where the side takes over, is not machined by the end.
void sweep_end(const SurfaceIndex& design, const Rails& rails, const EndProfile& end, int n_t, MachinedSurface& out) {
  const auto pose = [&](double t) {
    const Eigen::Vector3d a = rails.a.point(t), b = rails.b.point(t);
    return std::pair<Eigen::Vector3d, Eigen::Vector3d>(a, (b - a).normalized());
  };
  std::vector<Eigen::Vector3d> tips(static_cast<size_t>(n_t)), axes(static_cast<size_t>(n_t));
  for (int i = 0; i < n_t; ++i) std::tie(tips[size_t(i)], axes[size_t(i)]) = pose(double(i) / (n_t - 1));
  // Vertices farther than this from the tip's axis point cannot be nearer the end than its size.
  const Eigen::Vector2d top = end.profile[size_t(end.end_points)] - Eigen::Vector2d(end.tip_z, 0);
  const double reach = 3 * top.norm() + 2 * std::abs(end.tip_z);
  const auto at = [&](const Eigen::Vector3d& x, const Eigen::Vector3d& tip, const Eigen::Vector3d& axis) {
    const Eigen::Vector3d d = x - tip;
    const double z = d.dot(axis);
    return end_distance(end, z, (d - z * axis).norm());
  };
  const auto& V = design.mesh().vertices;
  out.design_by_end.assign(V.size(), 0);
#pragma omp parallel for schedule(dynamic, 256)
  for (int v = 0; v < int(V.size()); ++v) {
    const Eigen::Vector3d& x = V[size_t(v)];
    int best = -1, best_inner = -1;
    double best_d = INFINITY, best_inner_d = INFINITY;
    for (int i = 0; i < n_t; ++i) {
      if ((x - tips[size_t(i)]).squaredNorm() > reach * reach) continue;
      const double d = at(x, tips[size_t(i)], axes[size_t(i)]).distance;
      if (d < best_d) best_d = d, best = i;
      if (i > 0 && i < n_t - 1 && d < best_inner_d) best_inner_d = d, best_inner = i;
    }
    // A flat face over a floor is as near at many poses: an inner pose as near as the end one counts.
    if ((best == 0 || best == n_t - 1) && best_inner >= 0 && best_inner_d <= best_d + 1e-9 * (1 + std::abs(best_d)))
      best = best_inner, best_d = best_inner_d;
    if (best <= 0 || best >= n_t - 1) continue;  // not reached, or beyond the motion's ends
    double lo = double(best - 1) / (n_t - 1), hi = double(best + 1) / (n_t - 1);
    const double g = 0.5 * (std::sqrt(5.0) - 1);
    const auto f = [&](double t) {
      const auto [tip, axis] = pose(t);
      return at(x, tip, axis).distance;
    };
    double t1 = hi - g * (hi - lo), t2 = lo + g * (hi - lo), f1 = f(t1), f2 = f(t2);
    for (int k = 0; k < 40; ++k) {
      if (f1 <= f2) {
        hi = t2, t2 = t1, f2 = f1, t1 = hi - g * (hi - lo), f1 = f(t1);
      } else {
        lo = t1, t1 = t2, f1 = f2, t2 = lo + g * (hi - lo), f2 = f(t2);
      }
    }
    const auto [tip, axis] = pose(0.5 * (lo + hi));
    const EndDistance e = at(x, tip, axis);
    const double d = std::min(e.distance, best_d);
    if (!e.reached && !at(x, tips[size_t(best)], axes[size_t(best)]).reached) continue;
    double& dev = out.design_deviation[size_t(v)];
    if (!std::isfinite(dev) || d < dev) {
      dev = d;
      out.design_row[size_t(v)] = best;
      out.design_by_end[size_t(v)] = 1;
    }
  }
}

}  // namespace

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
  // Radii that describe no tool (a meridian folding back, tool_defect) have no end to sweep: such a
  // fit is never machinable and is judged by its side alone (detection meets them among candidates).
  std::optional<EndProfile> end;
  if (o.end && !tool_defect(tool, rails.length)) end = end_profile(meridian(tool, rails.length, 121), *o.end);
  out.omega = envelope_grid(motion, profile, o.grid_s, o.grid_t, out.sheet, 0.0, 1.0, end ? end->side_s : 0.0);
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
  out.design_by_end.assign(design.mesh().vertices.size(), 0);
  if (out.omega.mesh.faces.empty()) {
    if (end) sweep_end(design, rails, *end, o.grid_t, out);
    return out;
  }
  const SurfaceIndex omega_index(out.omega.mesh);
  const auto on_omega = omega_index.closest(design.mesh().vertices);
  const auto& normals = design.normals();
  for (size_t v = 0; v < on_omega.size(); ++v) {
    if (on_omega[v].on_boundary) continue;  // Ω does not reach this vertex
    // Nearest a folded sheet of Ω (a swallowtail of the envelope): not the surface the swept tool
    // leaves, so not a deviation of it (HECC diffuser: a patch with 1,408 folded faces claimed 23.6%
    // of the vane, its program's back-simulation cut 3.7%). Left to other patches, or uncovered.
    if (out.omega.folded[size_t(on_omega[v].face)]) continue;
    // The distance to Ω, signed by the side: Ω's nearest point can lie far aside with almost nothing
    // along Φ's normal where Ω crosses Φ steeply (a curled envelope, or one standing across Φ); the
    // normal component alone had called such vertices machined (HECC diffuser: a hub-row vertex 13.3 mm
    // from Ω, 0.002 mm along its normal).
    const Eigen::Vector3d to_omega = on_omega[v].point - design.mesh().vertices[v];
    out.design_deviation[v] = std::copysign(to_omega.norm(), to_omega.dot(out.tool_side * normals[v]));
    out.design_row[v] = out.omega.mesh.faces[size_t(on_omega[v].face)][0] / out.omega.n_s;
  }
  // The swept solid, not only its envelope: where the cutter at some pose holds a vertex deeper than
  // Ω's deviation says (the wings and the reversed branch of a swallowtail lie inside the swept
  // tool), Ω is not the surface left there. Judged at Ω's rows by the sphere at the vertex's
  // projection on the axis (a lower bound of the depth), between the end planes (above a rounded
  // end's side); such vertices are left uncovered by this patch.
  // And the converse: Ω's nearest point can lie across Φ from a vertex the cutter never reaches (a
  // sheet of Φ turned away from the tool, as where a blade's flank wraps round its leading edge):
  // a vertex the side's sections hold less than half as deep as Ω's overcut claims, less the tool's
  // travel between rows (slack), is not overcut by it (rotor 37: 0.67-1.15 mm "overcuts" of
  // leading-edge vertices the cutter stays 0.1 mm off). A real overcut D is at least D deep in a
  // convex cutter's side at the pose whose characteristic passes nearest, at most a row's travel
  // from a row; at a row, r(s) - ρ at the vertex's projection s (r the side's radius across the
  // axis there, ρ the vertex's distance from the axis) is at least its depth in the side (the way out
  // along ρ is that long), and beyond the side the vertex is outside it (there the clamped section
  // only over-states the reach).
  {
    const double s_lo = end ? end->side_s : 0.0, margin = 1e-4 * rails.length;
    double widest = 0;  // the cutter's largest radius
    for (int k = 0; k <= 100; ++k) widest = std::max(widest, profile.d(k / 100.0));
    // The motion at `rows` evenly spaced t: the axis' a end and a -> b, and a tool point's largest
    // move between neighbouring rows.
    struct Rows {
      std::vector<Eigen::Vector3d> at, along;
      double travel = 0;
    };
    const auto rows_of = [&](int rows) {
      Rows r;
      for (int i = 0; i < rows; ++i) {
        const double t = double(i) / (rows - 1);
        r.at.push_back(motion.a(t));
        r.along.push_back(motion.b(t) - motion.a(t));
      }
      for (int i = 0; i + 1 < rows; ++i) {
        const size_t j = size_t(i);
        const double ends = std::max((r.at[j + 1] - r.at[j]).norm(), (r.at[j + 1] + r.along[j + 1] - r.at[j] - r.along[j]).norm());
        r.travel = std::max(r.travel, ends + widest * (r.along[j + 1].normalized() - r.along[j].normalized()).norm());
      }
      return r;
    };
    // The side's radius across the axis at s, given d(s): d is the radius of the spheres it envelopes,
    // whose circles of contact lie off the perpendicular by the taper, so the section is
    // d / sqrt(1 - d'^2) (exact for a cone, to second order otherwise). With d(s) itself a vertex on
    // the envelope of a tapered side seems outside it by d (1 / cos - 1); an allowance of slope² times
    // the largest radius for that had kept every claim under two radii for a tool tapering 0.375 (test).
    const auto section = [&](double s, double d) {
      const double slope = profile.d_s(s) / rails.length;
      return d / std::sqrt(std::max(1e-6, 1 - slope * slope));
    };
    // A vertex x against the rows r: depth, by the spheres at its projection within the side; reach
    // (only for an overcut claim), by the sections there, the projection clamped to the side.
    struct Held {
      double depth = -INFINITY, reach = -INFINITY;
    };
    const auto held = [&](const Rows& r, const Eigen::Vector3d& x, bool claim) {
      Held h;
      for (size_t i = 0; i < r.at.size(); ++i) {
        const Eigen::Vector3d w = x - r.at[i];
        const double s = w.dot(r.along[i]) / r.along[i].squaredNorm(), sc = std::clamp(s, s_lo, 1.0);
        if (s != sc && !claim) continue;  // beyond the side: only an overcut claim needs its reach
        const double off = (w - sc * r.along[i]).norm(), d = profile.d(sc);
        if (claim) h.reach = std::max(h.reach, section(sc, d) - off);
        if (s == sc) h.depth = std::max(h.depth, d - off);
      }
      return h;
    };
    const Rows coarse = rows_of(o.grid_t);
    const double slack = coarse.travel + margin;
    const auto& verts = design.mesh().vertices;
    std::vector<char> undecided(verts.size(), 0);  // overcut claims that only finer rows can decide
#pragma omp parallel for schedule(static)
    for (int v = 0; v < int(verts.size()); ++v) {
      const double dev = out.design_deviation[size_t(v)];
      if (!std::isfinite(dev)) continue;
      const Held h = held(coarse, verts[size_t(v)], dev < 0);
      const bool deeper = h.depth > std::abs(dev) + margin;
      const bool unreached = dev < 0 && h.reach < 0.5 * -dev - slack;
      if (deeper || unreached) out.design_deviation[size_t(v)] = std::numeric_limits<double>::quiet_NaN();
      else if (dev < -20 * margin && h.reach < 0.5 * -dev) undecided[size_t(v)] = 1;
    }
    std::vector<int> claims;
    for (size_t v = 0; v < verts.size(); ++v)
      if (undecided[v]) claims.push_back(int(v));
    // Claims the rows' travel leaves undecided (Ω's rows are coarse for a motion that sweeps far:
    // rotor 37, a 30 mm tool whose points move up to 0.7 mm between rows claimed 0.171 mm where its
    // cutter, at 100 poses, comes no deeper than 0.001 mm): judged again at rows 16 times as dense.
    // Only claims deeper than 2e-3 of the tool's length: with no travel to allow for, the sections'
    // second-order error for a spline meridian would decide claims within a fine tolerance (the
    // detection test on exact spline-tool envelopes lost vertices of its one patch to it).
    if (!claims.empty()) {
      const Rows fine = rows_of(16 * (o.grid_t - 1) + 1);
#pragma omp parallel for schedule(dynamic, 16)
      for (int k = 0; k < int(claims.size()); ++k) {
        const size_t v = size_t(claims[size_t(k)]);
        if (held(fine, verts[v], true).reach < 0.5 * -out.design_deviation[v] - (fine.travel + margin))
          out.design_deviation[v] = std::numeric_limits<double>::quiet_NaN();
      }
    }
  }
  if (end) sweep_end(design, rails, *end, o.grid_t, out);
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
