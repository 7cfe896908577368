#include "postproc/verify.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <climits>
#include <cmath>
#include <filesystem>
#include <functional>
#include <tuple>

#include "core/errors.h"

namespace flankcam {

std::string VerifyOptions::validate() const {
  if (!(gouge_tolerance_mm >= 0) || !std::isfinite(gouge_tolerance_mm)) return "gouge_tolerance_mm: must be >= 0";
  if (!(link_clearance_mm >= 0) || !std::isfinite(link_clearance_mm)) return "link_clearance_mm: must be >= 0";
  if (!(step_mm > 0) || !std::isfinite(step_mm)) return "step_mm: must be > 0";
  if (!(cutter_slab_mm > 0) || !std::isfinite(cutter_slab_mm)) return "cutter_slab_mm: must be > 0";
  if (!(report_clearance_mm > 0) || !std::isfinite(report_clearance_mm)) return "report_clearance_mm: must be > 0";
  if (!(cl_tolerance_mm > 0) || !std::isfinite(cl_tolerance_mm)) return "cl_tolerance_mm: must be > 0";
  if (!(cl_angle_tolerance_deg > 0) || !std::isfinite(cl_angle_tolerance_deg)) return "cl_angle_tolerance_deg: must be > 0";
  if (apart.cut_part && (!(apart.design_gouge_tolerance_mm >= 0) || !std::isfinite(apart.design_gouge_tolerance_mm)))
    return "design_gouge_tolerance_mm: must be >= 0 when the cut is judged apart";
  return {};
}

std::string VerifyHit::kind() const {
  if (!rapid && component == Component::Tool) return "gouge";
  return depth_mm > 0 ? "collision" : "clearance";
}

std::string VerifyHit::what(double clearance_mm) const {
  if (kind() == "clearance")
    return fmt::format("{} {:.4f} mm from the part, inside the rapid clearance of {} mm", to_string(component), -depth_mm,
                       clearance_mm);
  return fmt::format("{} {} {:.4f} mm deep", to_string(component), kind(), depth_mm);
}

std::string VerifyReport::first_problem(const std::string& file) const {
  if (clean()) return {};
  int first = INT_MAX;
  for (const VerifyHit& h : hits) first = std::min(first, h.line);
  for (const ClDeviation& d : cl_deviations) first = std::min(first, d.line);
  const std::string tail =
      fmt::format("; {} block(s) hit the part or come inside the rapid clearance, {} cutting block(s) off the CL-data",
                  hits.size(), cl_deviations.size());
  const VerifyHit* worst = nullptr;  // the first line's deepest hit
  for (const VerifyHit& h : hits)
    if (h.line == first && (!worst || h.depth_mm > worst->depth_mm)) worst = &h;
  if (worst) {
    const VerifyHit& h = *worst;
    return fmt::format("{}:{}: {} at ({:.3f}, {:.3f}, {:.3f}) in {} {} ({})", file, h.line, h.what(link_clearance_mm),
                       h.point.x(), h.point.y(), h.point.z(),
                       h.tool_change ? "the tool change before motion block" : "motion block", h.block,
                       h.tool_change ? "tool change" : h.rapid ? "rapid" : "feed") +
           tail;
  }
  const ClDeviation& d = *std::find_if(cl_deviations.begin(), cl_deviations.end(),
                                       [&](const ClDeviation& c) { return c.line == first; });
  return fmt::format("{}:{}: cutting block off the CL-data by {:.3f} mm (axis {:.3f} deg) with the tip at ({:.3f}, {:.3f}, "
                     "{:.3f}) in motion block {} (feed)",
                     file, d.line, d.deviation_mm, d.angle_deg, d.tip.x(), d.tip.y(), d.tip.z(), d.block) +
         tail;
}

Eigen::Vector3d lead_direction(const SurfaceIndex& part, const ToolPose& p, double cutter_length_mm) {
  const Eigen::Vector3d mid = p.tip + 0.5 * cutter_length_mm * p.axis;
  Eigen::Vector3d v = mid - part.closest(mid).point;
  v -= v.dot(p.axis) * p.axis;
  return v.norm() > 1e-6 ? Eigen::Vector3d(v.normalized()) : p.axis;
}

std::vector<Eigen::Vector3d> lead_offsets(const Eigen::Vector3d& normal, const Eigen::Vector3d& axis) {
  std::vector<Eigen::Vector3d> out;
  for (const double lift : {0.0, 0.5, 1.0})
    for (const double deg : {0.0, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0, 90.0, -90.0})
      out.push_back(Eigen::AngleAxisd(deg * M_PI / 180, axis) * normal + lift * axis);
  return out;
}

bool is_cl_data_file(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".apt" || ext == ".cls";
}

Dialect dialect_of_file(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".nc") return Dialect::Iso;
  if (ext == ".ngc") return Dialect::LinuxCnc;
  if (ext == ".h") return Dialect::Heidenhain;
  if (ext == ".mpf") return Dialect::Sinumerik;
  throw InputError(path + ": unknown program type '" + ext + "' (.nc iso, .ngc linuxcnc, .h heidenhain, .mpf sinumerik, "
                   ".apt CL-data)");
}

ToolAssembly assembly_from_meridian(const std::vector<Eigen::Vector2d>& meridian, const ToolAssembly& holder) {
  ToolAssembly a = holder;
  a.cutter = cutter_from_meridian(meridian);
  if (std::string why = a.validate(); !why.empty()) throw InputError(why);
  return a;
}

namespace {

constexpr double kDeg = M_PI / 180;

// The solid of revolution: radius at z (from the tip) and the component there.
struct Body {
  const ToolAssembly& a;
  double L, total;
  explicit Body(const ToolAssembly& t) : a(t), L(t.cutter_length()), total(t.total_length()) {}
  [[nodiscard]] double radius(double z, Component* which) const {
    const auto& c = a.cutter;
    if (z <= L) {
      *which = Component::Tool;
      if (z <= c.front().x()) return c.front().y();
      const auto it = std::upper_bound(c.begin(), c.end(), z, [](double v, const Eigen::Vector2d& p) { return v < p.x(); });
      if (it == c.end()) return c.back().y();
      const Eigen::Vector2d &p = *(it - 1), &q = *it;
      return p.y() + (q.y() - p.y()) * (z - p.x()) / (q.x() - p.x());
    }
    if (z < L + a.shank_length || a.holder_length + a.holder_cylinder_length == 0) {
      *which = Component::Shank;
      return a.shank_length > 0 ? 0.5 * a.shank_diameter : 0;
    }
    *which = Component::Holder;
    const double z0 = L + a.shank_length;
    if (z < z0 + a.holder_length)
      return 0.5 * (a.holder_diameter + (a.holder_diameter_far - a.holder_diameter) * (z - z0) / a.holder_length);
    return 0.5 * a.holder_diameter_far;
  }
  // Gap between a part point and the solid (negative: inside, as deep as its way out), and where.
  [[nodiscard]] double gap(const ToolPose& pose, const Eigen::Vector3d& x, Component* which) const {
    const Eigen::Vector3d d = x - pose.tip;
    const double zq = d.dot(pose.axis), rho = (d - zq * pose.axis).norm();
    if (zq < 0) {
      const double r = radius(0, which);
      return rho <= r ? -zq : std::hypot(zq, rho - r);
    }
    if (zq > total) {
      const double r = radius(std::nextafter(total, 0.0), which);
      return rho <= r ? zq - total : std::hypot(zq - total, rho - r);
    }
    const double g = rho - radius(zq, which);
    if (g >= 0) return g;
    // Inside: the shallower of the radial way out and (cutter) the way out through the tip face.
    return *which == Component::Tool ? -std::min(-g, zq) : g;
  }
};

struct AxialSample {
  double z, reach;  // a part point farther than reach from the axis point is beyond the report distance
  double lo, hi;    // its slab (z from the tip), judged on its own when the nearest point lies beyond the tool's ends
};

std::vector<AxialSample> axial_samples(const ToolAssembly& a, const VerifyOptions& o) {
  const Body b(a);
  std::vector<AxialSample> s;
  Component c;
  const auto add_range = [&](double z0, double z1, double h) {
    if (!(z1 > z0)) return;
    const int n = std::max(1, int(std::ceil((z1 - z0) / h)));
    for (int k = 0; k <= n; ++k) {
      const double z = z0 + (z1 - z0) * k / n, half = 0.5 * (z1 - z0) / n;
      double r = 0;
      for (double zz : {std::max(z0, z - half), z, std::min(z1, z + half)})
        r = std::max(r, b.radius(std::min(zz, std::nextafter(b.total, 0.0)), &c));
      s.push_back({z, std::hypot(half, r) + o.report_clearance_mm, std::max(z0, z - half), std::min(z1, z + half)});
    }
  };
  add_range(0, b.L, o.cutter_slab_mm);
  add_range(b.L, b.total, 1.0);
  return s;
}

struct SimBlock {
  int block = 0, line = 0, tool = 0;
  bool rapid = false, tool_change = false;
  ToolPose start;                   // where the block starts (the previous block's end)
  const VerifyTool* vt = nullptr;
  std::vector<ToolPose> positions;  // the block's end included, its start (the previous end) not
  std::vector<Joints> programmed;   // per position: the axis values as programmed (NC programs only)
  double minutes = 0;
};

// Sweeps every block's positions: per block and component the smallest gap, and the hits.
// Rapids meet the whole part. Feed blocks meet it too, unless the cut is judged apart
// (VerifyOptions::cut_part with a design surface): then the part without Φ's twin and Φ itself, each
// with its own gouge tolerance.
void sweep(const SurfaceIndex& part, const SurfaceIndex* design, const std::vector<SimBlock>& blocks, const VerifyOptions& o,
           VerifyReport& rep) {
  struct Judge {  // one surface the assembly is swept against, with what a query there last found
    const SurfaceIndex* surface;
    double gouge_tolerance_mm;
    std::vector<Eigen::Vector3d> last;
    std::vector<double> slack;
  };
  std::vector<Judge> judges{{&part, o.gouge_tolerance_mm, {}, {}}};
  const bool apart = o.apart.cut_part && design;
  if (apart) {
    judges.push_back({o.apart.cut_part, o.gouge_tolerance_mm, {}, {}});
    judges.push_back({design, o.apart.design_gouge_tolerance_mm, {}, {}});
  }
  const VerifyTool* current = nullptr;
  std::vector<AxialSample> samples;
  for (const SimBlock& sb : blocks) {
    if (sb.vt != current) {
      current = sb.vt;
      samples = axial_samples(current->assembly, o);
      for (Judge& j : judges) {
        j.last.assign(samples.size(), Eigen::Vector3d::Constant(INFINITY));
        j.slack.assign(samples.size(), -1);
      }
    }
    const Body body(current->assembly);
    VerifiedBlock vb;
    vb.block = sb.block, vb.line = sb.line, vb.rapid = sb.rapid, vb.tool = sb.tool, vb.minutes = sb.minutes;
    vb.tool_change = sb.tool_change;
    vb.min_clearance_mm.fill(o.report_clearance_mm);
    std::array<VerifyHit, 3> worst;
    for (auto& w : worst) w.depth_mm = -INFINITY;
    const size_t first = apart && !sb.rapid ? 1 : 0, end = apart && !sb.rapid ? 3 : 1;
    for (const ToolPose& pose : sb.positions) {
      ++rep.positions;
      for (size_t jj = first; jj < end; ++jj) {
        Judge& j = judges[jj];
        for (size_t k = 0; k < samples.size(); ++k) {
          const Eigen::Vector3d c = pose.tip + samples[k].z * pose.axis;
          if (j.slack[k] > 0 && (c - j.last[k]).norm() < j.slack[k]) continue;
          const Footpoint f = j.surface->closest(c);
          j.last[k] = c;
          j.slack[k] = f.distance - samples[k].reach;
          if (j.slack[k] > 0) continue;
          Component comp;
          double g = body.gap(pose, f.point, &comp);
          Eigen::Vector3d point = f.point;
          // The nearest part point beyond the tool's ends (in the bulge of the sample's ball: a floor
          // under the tip) can hide a part entering the tool beside it: judged too, as the collision
          // check does (beside_nearest_points).
          if (const double zq = (f.point - pose.tip).dot(pose.axis); zq < 0 || zq > body.total) {
            Component tip;
            for (const Footpoint& q : beside_nearest_points(*j.surface, pose, samples[k].z, samples[k].lo, samples[k].hi, f.point,
                                                            body.radius(0, &tip), j.gouge_tolerance_mm)) {
              Component cq;
              if (q.face >= 0)
                if (const double gq = body.gap(pose, q.point, &cq); gq < g) g = gq, comp = cq, point = q.point;
            }
          }
          double& mc = vb.min_clearance_mm[size_t(comp)];
          mc = std::min(mc, g);
          bool hit = sb.rapid ? g < o.link_clearance_mm : (comp == Component::Tool ? -g > j.gouge_tolerance_mm : g < 0);
          // judge 1, the part without Φ's twin: its coarse edges along the twin's hole are Φ's
          if (hit && jj == 1 && comp == Component::Tool && left_to_design(*design, point, o.apart.design_within_mm)) hit = false;
          if (hit && -g > worst[size_t(comp)].depth_mm) {
            VerifyHit& h = worst[size_t(comp)];
            h.block = sb.block, h.line = sb.line, h.rapid = sb.rapid, h.component = comp;
            h.tool_change = sb.tool_change;
            h.depth_mm = -g;
            h.point = point;
            h.position = int(rep.positions - 1);
          }
        }
      }
    }
    for (const VerifyHit& h : worst)
      if (std::isfinite(h.depth_mm)) rep.hits.push_back(h);
    rep.cycle_minutes += sb.minutes;
    if (!sb.rapid) rep.cut_minutes += sb.minutes;
    rep.blocks.push_back(vb);
  }
}

// Machined deviation of the design surface: per vertex the signed gap to the nearest cutter position
// of the feed blocks (the swept cutter, sampled at the blocks' positions).
Deviation design_deviation(const SurfaceIndex& design, const std::vector<SimBlock>& blocks, double tol_mm) {
  constexpr double kReach = 0.5;  // mm: a vertex farther than this from every cutter position is "not reached"
  Deviation dev;
  dev.tolerance_mm = tol_mm;
  const auto& verts = design.mesh().vertices;
  dev.deviation_mm.assign(verts.size(), std::nan(""));
  std::vector<double> best(verts.size(), INFINITY);
  for (const SimBlock& sb : blocks) {
    if (sb.rapid) continue;
    const Body body(sb.vt->assembly);
    double rmax = 0;
    for (const auto& c : sb.vt->assembly.cutter) rmax = std::max(rmax, c.y());
    const double bound = std::hypot(0.5 * body.L, rmax) + kReach;
    for (const ToolPose& pose : sb.positions) {
      const Eigen::Vector3d mid = pose.tip + 0.5 * body.L * pose.axis;
      for (size_t v = 0; v < verts.size(); ++v) {
        if ((verts[v] - mid).squaredNorm() > bound * bound) continue;
        const Eigen::Vector3d d = verts[v] - pose.tip;
        const double zq = d.dot(pose.axis);
        if (zq < 0 || zq > body.L) continue;
        Component c;
        const double g = (d - zq * pose.axis).norm() - body.radius(zq, &c);
        best[v] = std::min(best[v], g);  // an overcut anywhere wins, else the nearest pass
      }
    }
  }
  for (size_t v = 0; v < verts.size(); ++v) {
    if (!(std::abs(best[v]) <= kReach)) continue;
    dev.deviation_mm[v] = best[v];
    ++dev.reached;
    dev.within += std::abs(best[v]) <= tol_mm;
  }
  return dev;
}

// The positions as swept, in order, for the 3D view.
std::vector<VerifiedPosition> motion_of(const std::vector<SimBlock>& blocks) {
  std::vector<VerifiedPosition> out;
  for (size_t b = 0; b < blocks.size(); ++b)
    for (size_t k = 0; k < blocks[b].positions.size(); ++k)
      out.push_back({blocks[b].positions[k], k < blocks[b].programmed.size() ? blocks[b].programmed[k] : Joints{}, int(b)});
  return out;
}

const VerifyTool& tool_for(const std::vector<VerifyTool>& tools, int number) {
  for (const VerifyTool& t : tools)
    if (t.number == number) return t;
  for (const VerifyTool& t : tools)
    if (t.number == 0) return t;
  if (tools.size() == 1) return tools.front();
  throw InputError(fmt::format("no tool given for T{} (its meridian: NAME-tool.csv beside the program, or --tool {}=FILE)",
                               number, number));
}

// Number of positions for a motion measured at a few interior fractions: the largest distance any
// point of the assembly (within `reach` of the tip) travels, divided by the step.
int steps_for(const std::function<ToolPose(double)>& at, double reach, double step) {
  constexpr int kProbe = 32;
  double travel = 0;
  ToolPose prev = at(0);
  for (int k = 1; k <= kProbe; ++k) {
    const ToolPose q = at(double(k) / kProbe);
    const double turn = std::acos(std::clamp(prev.axis.dot(q.axis), -1.0, 1.0));
    travel += (q.tip - prev.tip).norm() + turn * reach;
    prev = q;
  }
  return std::max(1, int(std::ceil(travel / step)));
}

bool same_rotary_angles(const Joints& a, const Joints& b) { return a.rotary == b.rotary; }

void check_machine_axes(const Machine& m, const Joints& a, const Joints& b, double minutes, const SimBlock& sb,
                        VerifyReport& rep) {
  for (int k = 0; k < 5; ++k) {
    const bool lin = k < 3;
    const double va = lin ? a.linear[k] : a.rotary[size_t(k - 3)], vb = lin ? b.linear[k] : b.rotary[size_t(k - 3)];
    const std::string name = lin ? m.linear[size_t(k)].name : m.rotary[size_t(k - 3)].name;
    const double lo = lin ? m.linear[size_t(k)].min_mm : m.rotary[size_t(k - 3)].min_deg;
    const double hi = lin ? m.linear[size_t(k)].max_mm : m.rotary[size_t(k - 3)].max_deg;
    const bool limited = lin || !m.rotary[size_t(k - 3)].continuous;
    if (limited && (vb < lo - 1e-3 || vb > hi + 1e-3))
      rep.violations.push_back({sb.block, sb.line, name, false, vb, vb < lo ? lo : hi});
    const double vmax = lin ? m.linear[size_t(k)].max_speed_mm_min : m.rotary[size_t(k - 3)].max_speed_deg_min;
    if (!sb.rapid && minutes > 0) {
      const double v = std::abs(vb - va) / minutes;
      // 4 decimals of position in a short block: allow their rounding.
      if (v > vmax * (1 + 1e-4) + 1e-4 / minutes) rep.violations.push_back({sb.block, sb.line, name, true, v, vmax});
    }
  }
}

}  // namespace

namespace {

// The CL motion of one tool: its feed segments (tip on a line, axis on a great circle).
struct ClMotion {
  const ClReference* ref = nullptr;
  std::vector<std::pair<ToolPose, ToolPose>> segments;
};

struct ClFit {
  double tip_mm = INFINITY, angle_deg = INFINITY;
  [[nodiscard]] double score(const VerifyOptions& o) const {
    return std::max(tip_mm / o.cl_tolerance_mm, angle_deg / o.cl_angle_tolerance_deg);
  }
};

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) / kDeg;
}

// The nearest point of the CL motion to a pose: per segment the parameter nearest the tip and the one
// nearest the axis, the better of the two by the tolerances.
ClFit nearest_on_cl(const ClMotion& cl, const ToolPose& p, const VerifyOptions& o) {
  ClFit best;
  double best_score = INFINITY;
  for (const auto& [a, b] : cl.segments) {
    const Eigen::Vector3d d = b.tip - a.tip;
    const double l2 = d.squaredNorm();
    double u_tip = l2 > 1e-18 ? std::clamp((p.tip - a.tip).dot(d) / l2, 0.0, 1.0) : 0.0;
    double u_axis = u_tip;
    const double turn = std::acos(std::clamp(a.axis.dot(b.axis), -1.0, 1.0));
    if (turn > 1e-9) {
      const Eigen::Vector3d e2 = (b.axis - a.axis.dot(b.axis) * a.axis).normalized();
      u_axis = std::clamp(std::atan2(p.axis.dot(e2), p.axis.dot(a.axis)) / turn, 0.0, 1.0);
    }
    for (const double u : {u_tip, u_axis}) {
      const ToolPose q = interpolate(a, b, u);
      const ClFit f{(p.tip - q.tip).norm(), angle_deg(p.axis, q.axis)};
      if (f.score(o) < best_score) best_score = f.score(o), best = f;
    }
  }
  return best;
}

// A lead block of the planner (nc_program.cpp plan_links, lead_point): the axis held, one end on the
// CL motion and every position on the straight line from there to a lead point along one of the
// planner's directions: the surface normal across the axis (lead_direction), turned about the axis by
// 20, 40, 60 or 90 degrees either way, lifted along the axis by none, half or all of the lead.
bool is_lead(const SimBlock& sb, const ClMotion& cl, const SurfaceIndex& part, const VerifyOptions& o) {
  const ToolPose& end = sb.positions.back();
  if (angle_deg(sb.start.axis, end.axis) > o.cl_angle_tolerance_deg) return false;
  const double L = sb.vt->assembly.cutter_length(), tol = o.cl_tolerance_mm;
  for (const ToolPose* on : {&sb.start, &end}) {
    if (nearest_on_cl(cl, *on, o).score(o) > 1) continue;
    const ToolPose& off = on == &end ? sb.start : end;
    const Eigen::Vector3d n = lead_direction(part, *on, L), run = off.tip - on->tip, axis = on->axis.normalized();
    for (const Eigen::Vector3d& offset : lead_offsets(n, axis)) {
      const Eigen::Vector3d dir = offset.normalized();
      if (!(run.dot(dir) > tol)) continue;
      bool along = true;
      for (const ToolPose& q : sb.positions) {
        const Eigen::Vector3d v = q.tip - on->tip;
        along &= (v - v.dot(dir) * dir).norm() <= tol && angle_deg(q.axis, on->axis) <= o.cl_angle_tolerance_deg;
      }
      if (along) return true;
    }
  }
  return false;
}

// Every feed block against the CL-data of its tool: the worst position of each block off it.
void compare_with_cl(const std::vector<SimBlock>& blocks, const std::vector<ClReference>& refs, const SurfaceIndex& part,
                     const VerifyOptions& o, VerifyReport& rep) {
  std::vector<ClMotion> motions;
  for (const ClReference& r : refs) {
    ClMotion cm;
    cm.ref = &r;
    for (size_t k = 1; k < r.cl.moves.size(); ++k)
      if (!r.cl.moves[k].rapid) cm.segments.emplace_back(r.cl.moves[k - 1].pose, r.cl.moves[k].pose);
    motions.push_back(std::move(cm));
  }
  // A tool's CL motions: one per patch it cuts (one shared or catalogue tool cuts several), else
  // those for every tool.
  const auto motions_for = [&](int tool) {
    std::vector<const ClMotion*> out;
    for (const ClMotion& c : motions)
      if (c.ref->tool == tool) out.push_back(&c);
    if (out.empty())
      for (const ClMotion& c : motions)
        if (c.ref->tool == 0) out.push_back(&c);
    return out;
  };
  rep.cl_compared = true;
  for (const SimBlock& sb : blocks) {
    if (sb.rapid || sb.tool_change || sb.block == 0) continue;
    const std::vector<const ClMotion*> cls = motions_for(sb.tool);
    if (cls.empty()) continue;  // a tool without CL-data: checked geometrically only
    if (std::all_of(cls.begin(), cls.end(), [](const ClMotion* c) { return c->segments.empty(); })) {
      rep.cl_deviations.push_back({sb.block, sb.line, INFINITY, INFINITY, sb.positions.back().tip});  // nothing may cut
      continue;
    }
    ++rep.cl_blocks;
    // The block against each motion of its tool; the one it follows best.
    ClFit worst{INFINITY, INFINITY};
    Eigen::Vector3d worst_tip = sb.positions.back().tip;
    for (const ClMotion* c : cls) {
      if (c->segments.empty()) continue;
      ClFit w{0, 0};
      Eigen::Vector3d at = sb.positions.back().tip;
      for (const ToolPose& q : sb.positions) {
        const ClFit f = nearest_on_cl(*c, q, o);
        if (f.score(o) > w.score(o)) w = f, at = q.tip;
      }
      if (w.score(o) < worst.score(o)) worst = w, worst_tip = at;
    }
    if (worst.score(o) <= 1) {
      rep.cl_max_deviation_mm = std::max(rep.cl_max_deviation_mm, worst.tip_mm);
      rep.cl_max_angle_deg = std::max(rep.cl_max_angle_deg, worst.angle_deg);
      continue;
    }
    if (std::any_of(cls.begin(), cls.end(), [&](const ClMotion* c) { return is_lead(sb, *c, part, o); })) continue;
    rep.cl_deviations.push_back({sb.block, sb.line, worst.tip_mm, worst.angle_deg, worst_tip});
  }
}

Eigen::Vector3d bounding_centre(const TriMesh& mesh, double* radius) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (const Eigen::Vector3d& v : mesh.vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  if (mesh.vertices.empty()) lo = hi = Eigen::Vector3d::Zero();
  *radius = 0.5 * (hi - lo).norm();
  return 0.5 * (lo + hi);
}

}  // namespace

VerifyReport verify_program(const std::vector<NcPoint>& program, const Machine& m, bool linuxcnc_trt,
                            const SurfaceIndex& part, const std::vector<VerifyTool>& tools, const VerifyOptions& o,
                            const SurfaceIndex* design, const std::vector<ClReference>& cl) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("verify options: " + why);
  if (tools.empty()) throw InputError("verify: no tool");
  VerifyReport rep;
  rep.link_clearance_mm = o.link_clearance_mm;
  if (program.empty()) return rep;
  // Values not yet stated at the start (the first blocks state Z, then the angles, then X Y) are
  // taken from where they are first stated: the simulation starts at the program's first position.
  std::vector<NcPoint> pts = program;
  for (int k = 0; k < 5; ++k) {
    const unsigned bit = 1u << k;
    auto first = std::find_if(pts.begin(), pts.end(), [&](const NcPoint& p) { return p.known & bit; });
    if (first == pts.end()) throw InputError(fmt::format("verify: the program never states axis {}", k < 3 ? "XYZ"[k] : '?'));
    const double v = k < 3 ? first->at.linear[k] : first->at.rotary[size_t(k - 3)];
    for (auto p = pts.begin(); p != first; ++p) (k < 3 ? p->at.linear[k] : p->at.rotary[size_t(k - 3)]) = v;
  }
  const auto tcp_of = [&](const NcPoint& p) { return linuxcnc_trt || p.tcp; };
  const auto value = [](Joints& j, int k) -> double& { return k < 3 ? j.linear[k] : j.rotary[size_t(k - 3)]; };
  // Machine joints of programmed values (under TCP the controller computes the linear joints).
  const auto machine_joints = [&](const Joints& at, bool tcp, double L) {
    if (!tcp) return at;
    const ToolPose pose{at.linear, forward(m, at, L).axis};
    return Joints{linear_joints(m, pose, at.rotary, L), at.rotary};
  };
  double part_radius = 0;
  const Eigen::Vector3d part_centre = bounding_centre(part.mesh(), &part_radius);

  std::vector<SimBlock> blocks;
  Joints cur = pts[0].at;  // the programmed values in force
  for (size_t i = 0; i < pts.size(); ++i) {
    const NcPoint& pt = pts[i];
    const VerifyTool& vt = tool_for(tools, pt.tool);
    const double L = vt.length_mm;
    const bool tcp = tcp_of(pt);
    if (i > 0 && pt.tool != pts[i - 1].tool) {
      // The tool-change macro with the old tool in machine joints: Z, then X Y, then the rotaries.
      const VerifyTool& old = tool_for(tools, pts[i - 1].tool);
      const auto& tc = m.tool_change.joints;
      Joints from = machine_joints(cur, tcp_of(pts[i - 1]), old.length_mm);
      for (int leg = 0; leg < 3; ++leg) {
        Joints to = from;
        if (leg == 0) to.linear.z() = tc[2] ? *tc[2] : m.linear[2].max_mm;
        for (int k : leg == 1 ? std::vector<int>{0, 1} : leg == 2 ? std::vector<int>{3, 4} : std::vector<int>{})
          if (tc[size_t(k)]) value(to, k) = *tc[size_t(k)];
        double minutes = 0;
        for (int k = 0; k < 5; ++k) {
          const double v = k < 3 ? m.linear[size_t(k)].max_speed_mm_min : m.rotary[size_t(k - 3)].max_speed_deg_min;
          minutes = std::max(minutes, std::abs(value(to, k) - value(from, k)) / v);
        }
        if (!(minutes > 0)) continue;
        SimBlock sb;
        sb.block = int(i), sb.line = pt.line, sb.rapid = true, sb.tool_change = true, sb.tool = pts[i - 1].tool;
        sb.vt = &old;
        sb.minutes = minutes;
        const auto joints_at = [&](double f) {
          Joints q;
          q.linear = (1 - f) * from.linear + f * to.linear;
          for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * from.rotary[k] + f * to.rotary[k];
          return q;
        };
        const auto at = [&](double f) { return forward(m, joints_at(f), old.length_mm); };
        sb.start = at(0);
        // With the rotaries held the tip moves on a line: beyond the part's bounding sphere, grown by the
        // assembly and the report distance, nothing can be touched (the travel may be a long way up).
        double f_end = 1;
        if (same_rotary_angles(from, to)) {
          const Eigen::Vector3d p0 = at(0).tip, d = at(1).tip - p0, c = p0 - part_centre;
          const double R = part_radius + old.assembly.total_length() + o.report_clearance_mm;
          const double a2 = d.squaredNorm(), b = c.dot(d), disc = b * b - a2 * (c.squaredNorm() - R * R);
          f_end = disc < 0 || a2 == 0 ? 0 : std::clamp((-b + std::sqrt(disc)) / a2, 0.0, 1.0);
        }
        const auto part_at = [&](double f) { return at(f * f_end); };
        const int n = f_end > 0 ? steps_for(part_at, old.assembly.total_length(), o.step_mm) : 0;
        for (int s = 1; s <= n; ++s) {  // the viewer shows the macro's machine joints
          sb.positions.push_back(part_at(double(s) / n));
          sb.programmed.push_back(joints_at(double(s) / n * f_end));
        }
        if (f_end < 1) sb.positions.push_back(at(1)), sb.programmed.push_back(joints_at(1));
        blocks.push_back(std::move(sb));
        from = to;
      }
      ++rep.tool_changes;
      cur = tcp ? Joints{forward(m, from, L).tip, from.rotary} : from;
    }
    Joints target = cur;
    for (int k = 0; k < 5; ++k)
      if (pt.stated & (1u << k)) value(target, k) = k < 3 ? pt.at.linear[k] : pt.at.rotary[size_t(k - 3)];
    SimBlock sb;
    sb.block = int(i), sb.line = pt.line, sb.rapid = pt.rapid, sb.tool = pt.tool;
    sb.vt = &vt;
    const auto programmed = [&](double f) {
      Joints q;
      q.linear = (1 - f) * cur.linear + f * target.linear;
      for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * cur.rotary[k] + f * target.rotary[k];
      return q;
    };
    const auto at = [&](double f) {
      const Joints q = programmed(f);
      const ToolPose fk = forward(m, q, L);
      return tcp ? ToolPose{q.linear, fk.axis} : fk;
    };
    sb.start = at(0);
    const int n = i == 0 ? 1 : steps_for(at, vt.assembly.total_length(), o.step_mm);
    for (int s = 1; s <= n; ++s) sb.positions.push_back(at(double(s) / n)), sb.programmed.push_back(programmed(double(s) / n));
    const Joints ja = machine_joints(cur, tcp, L), jb = machine_joints(target, tcp, L);
    if (pt.rapid) {
      for (int k = 0; k < 5; ++k) {
        const double d = k < 3 ? std::abs(jb.linear[k] - ja.linear[k]) : std::abs(jb.rotary[size_t(k - 3)] - ja.rotary[size_t(k - 3)]);
        const double v = k < 3 ? m.linear[size_t(k)].max_speed_mm_min : m.rotary[size_t(k - 3)].max_speed_deg_min;
        sb.minutes = std::max(sb.minutes, d / v);
      }
    } else if (pt.f > 0) {
      if (pt.inverse_time) {
        sb.minutes = 1 / pt.f;
      } else {
        double dist = (target.linear - cur.linear).norm();
        if (dist < 1e-6) dist = std::hypot(target.rotary[0] - cur.rotary[0], target.rotary[1] - cur.rotary[1]);
        sb.minutes = dist / pt.f;
      }
    }
    check_machine_axes(m, ja, jb, sb.minutes, sb, rep);
    blocks.push_back(std::move(sb));
    cur = target;
  }
  sweep(part, design, blocks, o, rep);
  if (!cl.empty()) compare_with_cl(blocks, cl, part, o, rep);
  rep.motion = motion_of(blocks);
  if (design) rep.design = design_deviation(*design, blocks, o.apart.cut_part ? o.apart.design_gouge_tolerance_mm : o.gouge_tolerance_mm);
  return rep;
}

VerifyReport verify_text(const std::string& text, Dialect d, const std::string& file, const Machine& m,
                         const SurfaceIndex& part, const std::vector<VerifyTool>& tools, const VerifyOptions& o,
                         const SurfaceIndex* design, const std::vector<ClReference>& cl) {
  const std::vector<NcPoint> pts = parse_nc(text, d, {m.rotary[0].name, m.rotary[1].name}, file);
  return verify_program(pts, m, d == Dialect::LinuxCnc && m.controller.linuxcnc_trt, part, tools, o, design, cl);
}

VerifyReport verify_cl(const ClProgram& cl, const SurfaceIndex& part, const VerifyTool& tool, const VerifyOptions& o,
                       const SurfaceIndex* design) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("verify options: " + why);
  VerifyReport rep;
  rep.link_clearance_mm = o.link_clearance_mm;
  std::vector<SimBlock> blocks;
  for (size_t i = 0; i < cl.moves.size(); ++i) {
    const ClMove& mv = cl.moves[i];
    const ToolPose prev = i > 0 ? cl.moves[i - 1].pose : mv.pose;
    SimBlock sb;
    sb.block = int(i), sb.line = int(i) + 1, sb.rapid = mv.rapid, sb.tool = cl.tool, sb.vt = &tool;
    const auto at = [&](double f) { return interpolate(prev, mv.pose, f); };
    const int n = i == 0 ? 1 : steps_for(at, tool.assembly.total_length(), o.step_mm);
    for (int s = 1; s <= n; ++s) sb.positions.push_back(at(double(s) / n));
    if (!mv.rapid && mv.feed_mm_min > 0) sb.minutes = (mv.pose.tip - prev.tip).norm() / mv.feed_mm_min;
    blocks.push_back(std::move(sb));
  }
  sweep(part, design, blocks, o, rep);
  rep.motion = motion_of(blocks);
  if (design) rep.design = design_deviation(*design, blocks, o.apart.cut_part ? o.apart.design_gouge_tolerance_mm : o.gouge_tolerance_mm);
  return rep;
}

}  // namespace flankcam
