#include "core/collision.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <tuple>

#include "core/errors.h"

namespace flankcam {

const char* to_string(Component c) {
  switch (c) {
    case Component::Tool: return "tool";
    case Component::Shank: return "shank";
    default: return "holder";
  }
}

double ToolAssembly::total_length() const {
  return cutter_length() + shank_length + holder_length + holder_cylinder_length;
}

std::string ToolAssembly::validate() const {
  if (cutter.size() < 2) return "tool profile: at least two points";
  for (size_t j = 0; j < cutter.size(); ++j) {
    if (!std::isfinite(cutter[j].x()) || !(cutter[j].y() > 0)) return "tool profile: radii must be positive";
    if (j > 0 && !(cutter[j].x() > cutter[j - 1].x())) return "tool profile: z must increase";
  }
  if (std::abs(cutter.front().x()) > 1e-9) return "tool profile: must start at the tip (z = 0)";
  for (double v : {shank_length, shank_diameter, holder_length, holder_diameter, holder_diameter_far, holder_cylinder_length})
    if (!(v >= 0) || !std::isfinite(v)) return "holder: lengths and diameters must be >= 0";
  if (shank_length > 0 && !(shank_diameter > 0)) return "holder.shank_diameter: must be > 0 with a shank";
  if (holder_length > 0 && !(holder_diameter > 0 && holder_diameter_far > 0)) return "holder.diameter: must be > 0";
  return {};
}

std::string CollisionOptions::validate() const {
  if (!(clearance_mm > 0)) return "clearance: must be > 0 mm";
  if (!(gouge_tolerance_mm > 0)) return "gouge tolerance: must be > 0 mm";
  if (!(slab_mm >= 0)) return "slab: must be >= 0 mm";
  return {};
}

namespace {

// Radius of the cutter's spheres at z (linear between the given spheres).
double cutter_radius(const ToolAssembly& t, double z) {
  const auto& c = t.cutter;
  if (z <= c.front().x()) return c.front().y();
  if (z >= c.back().x()) return c.back().y();
  const auto it = std::upper_bound(c.begin(), c.end(), z, [](double v, const Eigen::Vector2d& p) { return v < p.x(); });
  const Eigen::Vector2d &p = *(it - 1), &q = *it;
  return p.y() + (q.y() - p.y()) * (z - p.x()) / (q.x() - p.x());
}

// Shank and holder: radius at z (z >= cutter length) and which component it is.
double body_radius(const ToolAssembly& t, double z, Component* which) {
  double z0 = t.cutter_length();
  if (z < z0 + t.shank_length || t.holder_length + t.holder_cylinder_length == 0) {
    *which = Component::Shank;
    return 0.5 * t.shank_diameter;
  }
  *which = Component::Holder;
  z0 += t.shank_length;
  if (z < z0 + t.holder_length)
    return 0.5 * (t.holder_diameter + (t.holder_diameter_far - t.holder_diameter) * (z - z0) / t.holder_length);
  return 0.5 * t.holder_diameter_far;
}

struct Sample {
  double z, reach;  // axial position; a part point farther than `reach` from the axis point cannot matter
  bool cutter;
  double radius;    // cutter: sphere radius there
};

struct Hit {
  double depth = -INFINITY;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
};

}  // namespace

CollisionReport check_collisions(const SurfaceIndex& part, const std::vector<ToolPose>& poses, const ToolAssembly& tool,
                                 const CollisionOptions& o) {
  if (auto e = tool.validate(); !e.empty()) throw InputError(e);
  if (auto e = o.validate(); !e.empty()) throw InputError(e);
  CollisionReport report;
  if (poses.empty()) return report;
  const double L = tool.cutter_length(), total = tool.total_length();

  // Axial samples. Cutter: spheres spaced so that the dip of their union between samples,
  // h^2 / (8 r), stays below a quarter of the gouge tolerance.
  std::vector<Sample> samples;
  double rmin = INFINITY;
  for (const auto& c : tool.cutter) rmin = std::min(rmin, c.y());
  const double hc = o.slab_mm > 0 ? o.slab_mm : std::sqrt(2 * rmin * o.gouge_tolerance_mm);
  const int nc = std::max(2, int(std::ceil(L / hc)) + 1);
  for (int k = 0; k < nc; ++k) {
    const double z = L * k / (nc - 1), r = cutter_radius(tool, z);
    samples.push_back({z, r + o.gouge_tolerance_mm, true, r});
  }
  // Shank and holder: samples every h from the cutter's end to the holder's end (both included),
  // each covering the half slabs on both sides with the ball around it.
  const double hb = o.slab_mm > 0 ? o.slab_mm : std::max(0.5, 2 * o.clearance_mm);
  const int nb = total > L ? std::max(1, int(std::ceil((total - L) / hb))) : -1;
  for (int k = 0; k <= nb; ++k) {
    const double z = L + (total - L) * k / nb, half = 0.5 * (total - L) / nb;
    Component c;
    double r = 0;
    for (double zz : {std::max(L, z - half), z, std::min(total, z + half)}) r = std::max(r, body_radius(tool, std::min(zz, total), &c));
    samples.push_back({z, std::hypot(half, r) + o.clearance_mm, false, r});
  }
  // Positions: the poses and enough steps between them that no point moves more than clearance / 2.
  std::vector<ToolPose> pos;
  std::vector<int> pose_of;  // input pose at or before each position
  std::vector<char> is_pose;
  for (size_t i = 0; i < poses.size(); ++i) {
    if (i > 0) {
      const ToolPose &p = poses[i - 1], &q = poses[i];
      const double angle = std::acos(std::clamp(p.axis.dot(q.axis), -1.0, 1.0));
      const double move = (q.tip - p.tip).norm() + angle * total;
      const int steps = std::max(1, int(std::ceil(move / (0.5 * o.clearance_mm))));
      for (int s = 1; s < steps; ++s) {
        pos.push_back(interpolate(p, q, double(s) / steps));
        pose_of.push_back(int(i) - 1);
        is_pose.push_back(0);
      }
    }
    pos.push_back({poses[i].tip, poses[i].axis.normalized()});
    pose_of.push_back(int(i));
    is_pose.push_back(1);
  }
  const int np = int(pos.size()), ns = int(samples.size());
  report.positions_checked = np;

  // Per sample, walk the positions; skip queries while the axis point has moved less than its
  // last distance to the part exceeded the reach (triangle inequality).
  std::vector<std::vector<std::pair<int, Hit>>> hits(static_cast<size_t>(ns));  // (position, hit)
  std::vector<long> queries(static_cast<size_t>(ns), 0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < ns; ++k) {
    const Sample& s = samples[size_t(k)];
    Eigen::Vector3d last = Eigen::Vector3d::Constant(INFINITY);
    double slack = -1;
    for (int p = 0; p < np; ++p) {
      const Eigen::Vector3d c = pos[size_t(p)].tip + s.z * pos[size_t(p)].axis;
      if (slack > 0 && (c - last).norm() < slack) continue;
      const Footpoint f = part.closest(c);
      ++queries[size_t(k)];
      last = c;
      slack = f.distance - s.reach;
      if (slack > 0) continue;
      Hit h;
      h.at = f.point;
      if (s.cutter) {
        // The cutter is the solid of revolution of the spheres' radii between its flat end faces: a
        // part point below the tip plane (a floor the tip stands on) is outside it, and a point inside
        // is as deep as its way out through the side or the bottom face.
        const Eigen::Vector3d d = f.point - pos[size_t(p)].tip;
        const double zq = d.dot(pos[size_t(p)].axis), rho = (d - zq * pos[size_t(p)].axis).norm();
        if (zq < -1e-9 * (1 + L) || zq > L) continue;  // beyond the cutter's end: the shank's samples see it
        h.depth = std::min(cutter_radius(tool, std::clamp(zq, 0.0, L)) - rho, std::max(zq, 0.0));
        if (h.depth <= o.gouge_tolerance_mm) continue;
      } else {
        // Exact gap between the part point and the solid of revolution (2D, in the axis' half plane).
        const Eigen::Vector3d d = f.point - pos[size_t(p)].tip;
        const double zq = d.dot(pos[size_t(p)].axis), rho = (d - zq * pos[size_t(p)].axis).norm();
        double gap;
        Component comp;
        const double eps = 1e-9 * (1 + total);
        if (zq < L - eps) {
          const double r = body_radius(tool, L, &comp);
          gap = rho <= r ? L - zq : std::hypot(L - zq, rho - r);
        } else if (zq > total + eps) {
          const double r = body_radius(tool, std::nextafter(total, 0.0), &comp);
          gap = rho <= r ? zq - total : std::hypot(zq - total, rho - r);
        } else {
          gap = rho - body_radius(tool, std::clamp(zq, L, std::nextafter(total, 0.0)), &comp);
        }
        h.depth = -gap;  // > 0: inside the body
        if (gap >= o.clearance_mm) continue;
      }
      hits[size_t(k)].emplace_back(p, h);
    }
  }
  for (long q : queries) report.queries += q;

  // Worst hit per position and component, then intervals of consecutive colliding positions.
  for (Component comp : {Component::Tool, Component::Shank, Component::Holder}) {
    std::vector<Hit> worst(static_cast<size_t>(np));
    for (int k = 0; k < ns; ++k) {
      const Sample& s = samples[size_t(k)];
      Component sc = Component::Tool;
      if (!s.cutter) body_radius(tool, s.z, &sc);
      if (sc != comp) continue;
      for (const auto& [p, h] : hits[size_t(k)])
        if (h.depth > worst[size_t(p)].depth) worst[size_t(p)] = h;
    }
    for (int p = 0; p < np;) {
      if (!std::isfinite(worst[size_t(p)].depth)) {
        ++p;
        continue;
      }
      CollisionInterval iv;
      iv.component = comp;
      iv.pose_begin = pose_of[size_t(p)];
      iv.max_depth_mm = -INFINITY;
      int q = p;
      for (; q < np && std::isfinite(worst[size_t(q)].depth); ++q)
        if (worst[size_t(q)].depth > iv.max_depth_mm) {
          iv.max_depth_mm = worst[size_t(q)].depth;
          iv.at = worst[size_t(q)].at;
          iv.worst_pose = pose_of[size_t(q)];
        }
      const int last = q - 1;
      iv.pose_end = pose_of[size_t(last)] + (is_pose[size_t(last)] ? 0 : 1);  // between poses: the next one
      report.intervals.push_back(iv);
      p = q;
    }
  }
  std::sort(report.intervals.begin(), report.intervals.end(),
            [](const CollisionInterval& a, const CollisionInterval& b) {
              return std::tie(a.pose_begin, a.component) < std::tie(b.pose_begin, b.component);
            });
  return report;
}

TriMesh assembly_mesh(const ToolAssembly& tool, const ToolPose& pose, int segments) {
  // Meridian: cutter spheres' radii, shank, holder; closed by the axis points at both ends.
  std::vector<Eigen::Vector2d> mer;
  for (const auto& c : tool.cutter) mer.push_back(c);
  const double L = tool.cutter_length();
  Component comp;
  if (tool.shank_length > 0) {
    mer.emplace_back(L, body_radius(tool, L, &comp));
    mer.emplace_back(L + tool.shank_length, 0.5 * tool.shank_diameter);
  }
  if (tool.holder_length > 0) {
    const double z0 = L + tool.shank_length;
    mer.emplace_back(z0, 0.5 * tool.holder_diameter);
    mer.emplace_back(z0 + tool.holder_length, 0.5 * tool.holder_diameter_far);
    if (tool.holder_cylinder_length > 0) mer.emplace_back(z0 + tool.holder_length + tool.holder_cylinder_length, 0.5 * tool.holder_diameter_far);
  }
  const Eigen::Vector3d e = pose.axis.normalized(), u = e.unitOrthogonal(), v = e.cross(u);
  TriMesh m;
  m.vertices.push_back(pose.tip + mer.front().x() * e);
  for (const auto& p : mer)
    for (int s = 0; s < segments; ++s) {
      const double a = 2 * M_PI * s / segments;
      m.vertices.push_back(pose.tip + p.x() * e + p.y() * (std::cos(a) * u + std::sin(a) * v));
    }
  m.vertices.push_back(pose.tip + mer.back().x() * e);
  const int rings = int(mer.size()), top = int(m.vertices.size()) - 1;
  for (int s = 0; s < segments; ++s) {
    const int s1 = (s + 1) % segments;
    m.faces.push_back({0, 1 + s1, 1 + s});
    for (int r = 0; r + 1 < rings; ++r) {
      const int a = 1 + r * segments, b = a + segments;
      m.faces.push_back({a + s, a + s1, b + s1});
      m.faces.push_back({a + s, b + s1, b + s});
    }
    const int last = 1 + (rings - 1) * segments;
    m.faces.push_back({top, last + s, last + s1});
  }
  return m;
}

}  // namespace flankcam
