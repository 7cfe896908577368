#include "core/collision.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <tuple>

#include "core/errors.h"
#include "core/tool_end.h"

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
    if (!std::isfinite(cutter[j].x()) || !(cutter[j].y() > 0 || (j == 0 && cutter[j].y() == 0)))
      return "tool profile: radii must be positive (only the tip, of a ball end, may be on the axis)";
    if (j > 0 && !(cutter[j].x() > cutter[j - 1].x())) return "tool profile: z must increase";
  }
  if (std::abs(cutter.front().x()) > 1e-9) return "tool profile: must start at the tip (z = 0)";
  for (double v : {shank_length, shank_diameter, holder_length, holder_diameter, holder_diameter_far, holder_cylinder_length})
    if (!(v >= 0) || !std::isfinite(v)) return "holder: lengths and diameters must be >= 0";
  if (shank_length > 0 && !(shank_diameter > 0)) return "holder.shank_diameter: must be > 0 with a shank";
  if (holder_length > 0 && !(holder_diameter > 0 && holder_diameter_far > 0)) return "holder.diameter: must be > 0";
  return {};
}

std::vector<Eigen::Vector2d> cutter_from_meridian(const std::vector<Eigen::Vector2d>& meridian) {
  std::vector<Eigen::Vector2d> cutter;
  for (const Eigen::Vector2d& zr : meridian)
    if (zr.x() > 1e-9 && (cutter.empty() || zr.x() > cutter.back().x())) {
      if (cutter.empty()) cutter.emplace_back(0.0, zr.y());
      if (cutter.size() == 1 && zr.y() == 0) continue;  // a ball end's tip on the axis (core/tool_end.h): once
      cutter.push_back(zr);
    } else if (std::abs(zr.x()) <= 1e-9 && cutter.empty()) {
      cutter.emplace_back(0.0, zr.y());
    }
  return cutter;
}

std::string CollisionOptions::validate() const {
  if (!(clearance_mm > 0)) return "clearance: must be > 0 mm";
  if (!(gouge_tolerance_mm > 0)) return "gouge tolerance: must be > 0 mm";
  if (!(slab_mm >= 0)) return "slab: must be >= 0 mm";
  if (max_positions < 1 || !(max_work >= 1)) return "max_positions, max_work: must be >= 1";
  return {};
}

namespace {

// The cutter's radius at z (linear between the given radii).
double cutter_radius(const ToolAssembly& t, double z) { return profile_radius(t.cutter, z); }

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

// The body's outline in the axis' half plane, (z from the tip, radius) and the component of the
// segment ending there: up the shank's side from the cutter's end, out along the holder's face, up its
// cone and cylinder, in along its far end to the axis.
struct BodyOutline {
  std::vector<Eigen::Vector2d> points;
  std::vector<Component> component;  // per point: the segment's ending there
  void add(const Eigen::Vector2d& p, Component c) { points.push_back(p), component.push_back(c); }
};
BodyOutline body_outline(const ToolAssembly& t) {
  const double L = t.cutter_length(), total = t.total_length();
  const double z1 = L + t.shank_length, z2 = z1 + t.holder_length;
  const double rs = 0.5 * t.shank_diameter;
  BodyOutline outline;
  outline.add({L, rs}, Component::Shank);
  if (t.shank_length > 0) outline.add({z1, rs}, Component::Shank);
  if (t.holder_length + t.holder_cylinder_length > 0) {
    outline.add({z1, 0.5 * t.holder_diameter}, Component::Holder);
    if (t.holder_length > 0) outline.add({z2, 0.5 * t.holder_diameter_far}, Component::Holder);
    outline.add({total, 0.5 * t.holder_diameter_far}, Component::Holder);
  }
  outline.add({total, 0.0}, outline.component.back());
  return outline;
}

// The signed gap between a point at height z above the tip and rho off the axis and the body (shank
// and holder as one solid of revolution, `outline` = body_outline(t)), and the component there.
// Inside, the radial depth (< 0). Outside, below the cutter's end, the distance to the shank's end
// (the cutter's own samples judge the cutter); from there up the exact distance to the outline (a
// point under the holder's face beside the shank is as far as the face, not as far as the shank).
// A point below the cutter's end within `shade` (its end radius and the gouge tolerance: the surface
// it touches there; -1 where the shank is wider than that end) is under the cutter's end face or
// inside the cutter: a narrower shank cannot reach it but through the cutter, so it is the cutter's
// alone (infinite gap; a Ø8 shank over a Ø9.7 cutter was held 0.5 mm off the blade's tip face the
// cutter touched). A wider shank's face overhangs the cutter and does reach what lies under it.
double body_gap(const ToolAssembly& t, const BodyOutline& outline, double z, double rho, double shade, Component* which) {
  const double L = t.cutter_length(), total = t.total_length();
  const double eps = 1e-9 * (1 + total);
  if (z < L - eps) {
    if (rho <= shade) {
      *which = Component::Shank;
      return INFINITY;
    }
    const double r = body_radius(t, L, which);
    return rho <= r ? L - z : std::hypot(L - z, rho - r);
  }
  if (z <= total + eps) {
    const double r = body_radius(t, std::clamp(z, L, std::nextafter(total, 0.0)), which);
    if (rho <= r) return rho - r;
  }
  const PolylinePoint near = polyline_nearest(outline.points, {z, rho});
  *which = outline.component[near.segment + 1];
  return near.distance;
}

struct Sample {
  double z, reach;  // axial position; a part point farther than `reach` from the axis point cannot matter
  bool cutter;
  double radius;    // cutter: sphere radius there
  // The slab (z from the tip) whose own nearest part point is judged too: always for shank and
  // holder; for the cutter when the nearest part point lies beyond its ends.
  double lo = 0, hi = 0;
};

struct Hit {
  double depth = -INFINITY;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  Component component = Component::Tool;
};

}  // namespace

std::vector<Footpoint> beside_nearest_points(const SurfaceIndex& part, const ToolPose& pose, double z, double lo, double hi,
                                             const Eigen::Vector3d& nearest, double tip_radius, double step) {
  const Eigen::Vector3d axis = pose.axis.normalized(), c = pose.tip + z * axis;
  const double base = pose.tip.dot(axis);
  const Eigen::Vector3d d = nearest - pose.tip, radial = d - d.dot(axis) * axis;
  if (lo != 0 || !(d.dot(axis) < 0) || !(step > 0) || !(hi > 0)) return {part.closest_in_slab(c, axis, base + lo, base + hi)};
  std::vector<Footpoint> out;
  for (double a = 0, b = std::min(step, hi); a < hi; a = b, b = std::min(2 * b, hi))
    out.push_back(part.closest_in_slab(c, axis, base + a, base + b));
  if (radial.norm() > 1e-9 * (1 + tip_radius)) out.push_back(part.closest(pose.tip + tip_radius * radial.normalized()));
  return out;
}

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
  // (A rounded end's radii fall to the tip's: its small radii are left out of the spacing, and each
  // sample's reach covers its slab of the profile.)
  double rmin = INFINITY, rmax = 0;
  for (const auto& c : tool.cutter) rmax = std::max(rmax, c.y());
  for (const auto& c : tool.cutter)
    if (c.y() >= 0.1 * rmax) rmin = std::min(rmin, c.y());
  const double hc = o.slab_mm > 0 ? o.slab_mm
                                  : std::sqrt(2 * rmin * (o.slab_tolerance_mm > 0 ? o.slab_tolerance_mm : o.gouge_tolerance_mm));
  const double hb = o.slab_mm > 0 ? o.slab_mm : std::max(0.5, 2 * o.clearance_mm);
  double sample_count = std::ceil(L / hc) + std::ceil((total - L) / hb) + 3;  // an upper bound (a cone's: below)
  if (!(sample_count <= o.max_work))
    throw InputError(fmt::format("collision check: the tool ({:g} mm long) would need {:.0f} axial samples, more than {}: "
                                 "raise the gouge tolerance or the clearance",
                                 total, sample_count, o.max_work));
  const int nc = std::max(2, int(std::ceil(L / hc)) + 1);
  for (int k = 0; k < nc; ++k) {
    const double z = L * k / (nc - 1), r = cutter_radius(tool, z), half = 0.5 * L / (nc - 1);
    double r_slab = r;
    for (double zz : {std::max(0.0, z - half), std::min(L, z + half)}) r_slab = std::max(r_slab, cutter_radius(tool, zz));
    for (const auto& c : tool.cutter)
      if (std::abs(c.x() - z) <= half) r_slab = std::max(r_slab, c.y());
    samples.push_back({z, std::max(r, std::hypot(half, r_slab)) + o.gouge_tolerance_mm, true, r, std::max(0.0, z - half), std::min(L, z + half)});
  }
  // Shank and holder: between the body's breaks (the cutter's end, the holder's face, the end of
  // its cone, its far end) samples every h or less, both ends included, a cone's so close that its
  // radius changes by at most a quarter of the clearance from one to the next; each sample's slab
  // reaches half way to its neighbours but never past a break, its ball enclosing the slab. Within a
  // slab the body's nearest part point is the one nearest the axis (up to the slab's sag), and the
  // samples at the breaks see the rims exactly. The slab, widened by the clearance, is queried for
  // its own nearest part point besides the whole part's: a nearer part point beside the shank cannot
  // hide a farther one that enters the holder through its face.
  std::vector<double> breaks{L};
  for (const double z : {L + tool.shank_length, L + tool.shank_length + tool.holder_length, total})
    if (z > breaks.back() + 1e-9 * (1 + total)) breaks.push_back(z);
  for (size_t b = 0; b + 1 < breaks.size(); ++b) {
    const double z0 = breaks[b], z1 = breaks[b + 1];
    Component c;
    const double r0 = body_radius(tool, z0 + 1e-6 * (z1 - z0), &c), r1 = body_radius(tool, z1 - 1e-6 * (z1 - z0), &c);
    double h = hb;
    if (std::abs(r1 - r0) > 1e-12 * (1 + r0)) h = std::min(h, 0.25 * o.clearance_mm * (z1 - z0) / std::abs(r1 - r0));
    if (!(double(samples.size()) + (z1 - z0) / h <= o.max_work))
      throw InputError(fmt::format("collision check: the tool's body ({:g} mm long) would need more than {} axial samples: "
                                   "raise the clearance",
                                   total - L, o.max_work));
    const int n = std::max(1, int(std::ceil((z1 - z0) / h)));
    const double half = 0.5 * (z1 - z0) / n;
    for (int k = 0; k <= n; ++k) {
      const double z = z0 + (z1 - z0) * k / n, lo = std::max(z0, z - half), hi = std::min(z1, z + half);
      const double r = std::max(r0 + (r1 - r0) * (lo - z0) / (z1 - z0), r0 + (r1 - r0) * (hi - z0) / (z1 - z0));
      samples.push_back({z, std::hypot(half, r) + o.clearance_mm, false, r, lo - o.clearance_mm, hi + o.clearance_mm});
    }
  }
  sample_count = double(samples.size());
  const BodyOutline outline = body_outline(tool);
  // Shaded only under a shank narrower than the cutter's end (a wider shank's face overhangs it).
  Component at_end;
  const double end_radius = cutter_radius(tool, L);
  const double shade = body_radius(tool, L, &at_end) < end_radius ? end_radius + o.gouge_tolerance_mm : -1.0;
  // Positions: the poses and enough steps between them that no point moves more than clearance / 2.
  // Counted first, so that an absurd motion (50 m at 0.5 mm) is refused before any work.
  std::vector<int> steps(poses.size(), 1);
  std::vector<double> step_tip(poses.size(), 0.0), step_angle(poses.size(), 0.0);  // per step, into pose i
  double positions = double(poses.size()), travel = 0;
  for (size_t i = 1; i < poses.size(); ++i) {
    const ToolPose &p = poses[i - 1], &q = poses[i];
    if (!p.tip.allFinite() || !q.tip.allFinite() || !p.axis.allFinite() || !q.axis.allFinite())
      throw InputError(fmt::format("collision check: pose {} is not finite", p.tip.allFinite() && p.axis.allFinite() ? i : i - 1));
    const double angle = std::acos(std::clamp(p.axis.normalized().dot(q.axis.normalized()), -1.0, 1.0));
    const double move = (q.tip - p.tip).norm() + angle * total;
    travel += move;
    const double n = std::max(1.0, std::ceil(move / (0.5 * o.clearance_mm)));
    positions += n - 1;
    if (!(positions <= o.max_positions && positions * sample_count <= o.max_work))
      throw InputError(fmt::format("collision check: the motion ({:g} mm of travel and more) checked every {:g} mm (half the "
                                   "clearance) at {:.0f} points along the tool needs more than {} positions or {} checks: "
                                   "raise the clearance or split the patch",
                                   travel, 0.5 * o.clearance_mm, sample_count, o.max_positions, o.max_work));
    steps[i] = int(n);
    step_tip[i] = (q.tip - p.tip).norm() / n;
    step_angle[i] = angle / n;
  }
  std::vector<ToolPose> pos;
  std::vector<int> pose_of;        // input pose at or before each position
  std::vector<char> is_pose;
  std::vector<double> tip_run, angle_run;  // accumulated tip travel (mm) and axis turn (rad) up to each position
  pos.reserve(size_t(positions));
  for (size_t i = 0; i < poses.size(); ++i) {
    for (int s = 1; s <= steps[i]; ++s) {
      const bool last = s == steps[i];
      pos.push_back(last ? ToolPose{poses[i].tip, poses[i].axis.normalized()} : interpolate(poses[i - 1], poses[i], double(s) / steps[i]));
      pose_of.push_back(last ? int(i) : int(i) - 1);
      is_pose.push_back(last);
      tip_run.push_back(tip_run.empty() ? 0 : tip_run.back() + step_tip[i]);
      angle_run.push_back(angle_run.empty() ? 0 : angle_run.back() + step_angle[i]);
    }
  }
  const int np = int(pos.size()), ns = int(samples.size());
  report.positions_checked = np;

  // Per sample, walk the positions; after a query whose distance exceeds the reach by `slack`, skip
  // every position the axis point cannot have travelled `slack` to (triangle inequality; its travel
  // is at most the tip's plus z times the axis' turn), found by bisection.
  std::vector<std::vector<std::pair<int, Hit>>> hits(static_cast<size_t>(ns));  // (position, hit)
  std::vector<long> queries(static_cast<size_t>(ns), 0);
  int samples_done = 0;
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < ns; ++k) {
    const Sample& s = samples[size_t(k)];
    const auto run = [&](int p) { return tip_run[size_t(p)] + s.z * angle_run[size_t(p)]; };
    for (int p = 0; p < np;) {
      const Eigen::Vector3d c = pos[size_t(p)].tip + s.z * pos[size_t(p)].axis;
      const Footpoint f = part.closest(c);
      ++queries[size_t(k)];
      const double slack = f.distance - s.reach;
      if (slack > 0) {
        int lo = p + 1, hi = np;  // first position whose travel from p may reach `slack`
        const double from = run(p);
        while (lo < hi) {
          const int mid = lo + (hi - lo) / 2;
          if (run(mid) - from < slack) lo = mid + 1; else hi = mid;
        }
        p = lo;
        continue;
      }
      const int here = p++;
      Hit h;
      h.at = f.point;
      if (s.cutter) {
        // The cutter is the solid of revolution of its radii between its flat end faces: a
        // part point below the tip plane (a floor the tip stands on) is outside it, and a point inside
        // is as deep as its way out through the side or the bottom face.
        const ToolPose& at = pos[size_t(here)];
        const auto depth_at = [&](const Eigen::Vector3d& point) -> double {
          const Eigen::Vector3d d = point - at.tip;
          const double zq = d.dot(at.axis), rho = (d - zq * at.axis).norm();
          if (zq < -1e-9 * (1 + L) || zq > L) return -INFINITY;  // beyond the cutter's end: the shank's samples see it
          return std::min(cutter_radius(tool, std::clamp(zq, 0.0, L)) - rho, std::max(zq, 0.0));
        };
        h.depth = depth_at(f.point);
        if (!std::isfinite(h.depth)) {
          // The nearest part point lies beyond the cutter's end, in the bulge of the sample's ball: it
          // can hide a part entering the cutter beside it, judged instead (beside_nearest_points).
          const std::vector<Footpoint> candidates =
              beside_nearest_points(part, at, s.z, s.lo, s.hi, f.point, cutter_radius(tool, 0), o.gouge_tolerance_mm);
          queries[size_t(k)] += long(candidates.size());
          for (const Footpoint& q : candidates)
            if (q.face >= 0)
              if (const double dq = depth_at(q.point); dq > h.depth) h.depth = dq, h.at = q.point;
          if (!std::isfinite(h.depth)) continue;
        }
        if (!(h.depth > o.gouge_tolerance_mm)) continue;
        if (o.design && left_to_design(*o.design, h.at, o.design_within_mm)) continue;
      } else {
        // Exact gap between the part point and the solid of revolution (2D, in the axis' half plane),
        // at the whole part's nearest point and at the slab's own.
        const ToolPose& at = pos[size_t(here)];
        const auto judge = [&](const Eigen::Vector3d& point) {
          const Eigen::Vector3d d = point - at.tip;
          const double zq = d.dot(at.axis), rho = (d - zq * at.axis).norm();
          Component comp;
          const double gap = body_gap(tool, outline, zq, rho, shade, &comp);
          if (-gap > h.depth) h.depth = -gap, h.at = point, h.component = comp;  // depth > 0: inside the body
        };
        judge(f.point);
        const double base = at.tip.dot(at.axis);
        const Footpoint fs = part.closest_in_slab(c, at.axis, base + s.lo, base + s.hi);
        ++queries[size_t(k)];
        if (fs.face >= 0) judge(fs.point);
        // (A point on the widened slab's end plane, exactly the clearance off the body, is clear however
        // its gap rounds.)
        if (-h.depth >= o.clearance_mm * (1 - 1e-9)) continue;
      }
      hits[size_t(k)].emplace_back(here, h);
    }
    if (o.progress) {
#pragma omp critical(flankcam_collision_progress)
      o.progress(double(++samples_done) / ns);
    }
  }
  for (long q : queries) report.queries += q;

  // Worst hit per position and component, then intervals of consecutive colliding positions.
  for (Component comp : {Component::Tool, Component::Shank, Component::Holder}) {
    std::vector<Hit> worst(static_cast<size_t>(np));
    for (int k = 0; k < ns; ++k)
      for (const auto& [p, h] : hits[size_t(k)])
        if (h.component == comp && h.depth > worst[size_t(p)].depth) worst[size_t(p)] = h;
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
  // Meridian: the cutter's radii, shank, holder; closed by the axis points at both ends.
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
