#include "postproc/verify.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
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
  return {};
}

std::string VerifyHit::kind() const { return !rapid && component == Component::Tool ? "gouge" : "collision"; }

std::string VerifyReport::first_problem(const std::string& file) const {
  if (hits.empty()) return {};
  const VerifyHit& h = *std::max_element(hits.begin(), hits.end(), [](const VerifyHit& a, const VerifyHit& b) {
    return std::make_tuple(-a.line, a.depth_mm) < std::make_tuple(-b.line, b.depth_mm);  // the first line, its deepest
  });
  return fmt::format("{}:{}: {} {} {:.3f} mm deep at ({:.3f}, {:.3f}, {:.3f}) in motion block {} ({}); {} block(s) "
                     "hit the part",
                     file, h.line, to_string(h.component), h.kind(), h.depth_mm, h.point.x(), h.point.y(), h.point.z(),
                     h.block, h.rapid ? "rapid" : "feed", hits.size());
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
  a.cutter.clear();
  // From the tip: a meridian sampled from a little above it starts with its first radius at z = 0.
  for (const Eigen::Vector2d& zr : meridian)
    if (zr.x() > 1e-9 && (a.cutter.empty() || zr.x() > a.cutter.back().x())) {
      if (a.cutter.empty()) a.cutter.emplace_back(0.0, zr.y());
      a.cutter.push_back(zr);
    } else if (std::abs(zr.x()) <= 1e-9 && a.cutter.empty()) {
      a.cutter.emplace_back(0.0, zr.y());
    }
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
      s.push_back({z, std::hypot(half, r) + o.report_clearance_mm});
    }
  };
  add_range(0, b.L, o.cutter_slab_mm);
  add_range(b.L, b.total, 1.0);
  return s;
}

struct SimBlock {
  int block = 0, line = 0, tool = 0;
  bool rapid = false;
  const VerifyTool* vt = nullptr;
  std::vector<ToolPose> positions;  // the block's end included, its start (the previous end) not
  std::vector<Joints> programmed;   // per position: the axis values as programmed (NC programs only)
  double minutes = 0;
};

// Sweeps every block's positions: per block and component the smallest gap, and the hits.
void sweep(const SurfaceIndex& part, const std::vector<SimBlock>& blocks, const VerifyOptions& o, VerifyReport& rep) {
  const VerifyTool* current = nullptr;
  std::vector<AxialSample> samples;
  std::vector<Eigen::Vector3d> last;
  std::vector<double> slack;
  for (const SimBlock& sb : blocks) {
    if (sb.vt != current) {
      current = sb.vt;
      samples = axial_samples(current->assembly, o);
      last.assign(samples.size(), Eigen::Vector3d::Constant(INFINITY));
      slack.assign(samples.size(), -1);
    }
    const Body body(current->assembly);
    VerifiedBlock vb;
    vb.block = sb.block, vb.line = sb.line, vb.rapid = sb.rapid, vb.tool = sb.tool, vb.minutes = sb.minutes;
    vb.min_clearance_mm.fill(o.report_clearance_mm);
    std::array<VerifyHit, 3> worst;
    for (auto& w : worst) w.depth_mm = -INFINITY;
    for (const ToolPose& pose : sb.positions) {
      ++rep.positions;
      for (size_t k = 0; k < samples.size(); ++k) {
        const Eigen::Vector3d c = pose.tip + samples[k].z * pose.axis;
        if (slack[k] > 0 && (c - last[k]).norm() < slack[k]) continue;
        const Footpoint f = part.closest(c);
        last[k] = c;
        slack[k] = f.distance - samples[k].reach;
        if (slack[k] > 0) continue;
        Component comp;
        const double g = body.gap(pose, f.point, &comp);
        double& mc = vb.min_clearance_mm[size_t(comp)];
        mc = std::min(mc, g);
        const bool hit = sb.rapid ? g < o.link_clearance_mm
                                  : (comp == Component::Tool ? -g > o.gouge_tolerance_mm : g < 0);
        if (hit && -g > worst[size_t(comp)].depth_mm) {
          VerifyHit& h = worst[size_t(comp)];
          h.block = sb.block, h.line = sb.line, h.rapid = sb.rapid, h.component = comp;
          h.depth_mm = -g;
          h.point = f.point;
          h.position = int(rep.positions - 1);
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

VerifyReport verify_program(const std::vector<NcPoint>& program, const Machine& m, bool linuxcnc_trt,
                            const SurfaceIndex& part, const std::vector<VerifyTool>& tools, const VerifyOptions& o,
                            const SurfaceIndex* design) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("verify options: " + why);
  if (tools.empty()) throw InputError("verify: no tool");
  VerifyReport rep;
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
  std::vector<SimBlock> blocks;
  for (size_t i = 0; i < pts.size(); ++i) {
    const NcPoint& pt = pts[i];
    const NcPoint& prev = i > 0 ? pts[i - 1] : pts[i];
    SimBlock sb;
    sb.block = int(i), sb.line = pt.line, sb.rapid = pt.rapid, sb.tool = pt.tool;
    sb.vt = &tool_for(tools, pt.tool);
    const double L = sb.vt->length_mm;
    const bool tcp = tcp_of(pt);
    const auto programmed = [&](double f) {
      Joints q;
      q.linear = (1 - f) * prev.at.linear + f * pt.at.linear;
      for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * prev.at.rotary[k] + f * pt.at.rotary[k];
      return q;
    };
    const auto at = [&](double f) {
      const Joints q = programmed(f);
      const ToolPose fk = forward(m, q, L);
      return tcp ? ToolPose{q.linear, fk.axis} : fk;
    };
    const int n = i == 0 ? 1 : steps_for(at, sb.vt->assembly.total_length(), o.step_mm);
    for (int s = 1; s <= n; ++s) sb.positions.push_back(at(double(s) / n)), sb.programmed.push_back(programmed(double(s) / n));
    // Machine joints at both ends (under TCP the controller computes the linear joints).
    const auto joints = [&](const NcPoint& p) {
      if (!tcp_of(p)) return p.at;
      const ToolPose pose{p.at.linear, forward(m, p.at, L).axis};
      return Joints{linear_joints(m, pose, p.at.rotary, L), p.at.rotary};
    };
    const Joints ja = joints(prev), jb = joints(pt);
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
        double dist = (pt.at.linear - prev.at.linear).norm();
        if (dist < 1e-6) dist = std::hypot(pt.at.rotary[0] - prev.at.rotary[0], pt.at.rotary[1] - prev.at.rotary[1]);
        sb.minutes = dist / pt.f;
      }
    }
    check_machine_axes(m, ja, jb, sb.minutes, sb, rep);
    blocks.push_back(std::move(sb));
  }
  sweep(part, blocks, o, rep);
  rep.motion = motion_of(blocks);
  if (design) rep.design = design_deviation(*design, blocks, o.gouge_tolerance_mm);
  return rep;
}

VerifyReport verify_text(const std::string& text, Dialect d, const std::string& file, const Machine& m,
                         const SurfaceIndex& part, const std::vector<VerifyTool>& tools, const VerifyOptions& o,
                         const SurfaceIndex* design) {
  const std::vector<NcPoint> pts = parse_nc(text, d, {m.rotary[0].name, m.rotary[1].name}, file);
  return verify_program(pts, m, d == Dialect::LinuxCnc && m.controller.linuxcnc_trt, part, tools, o, design);
}

VerifyReport verify_cl(const ClProgram& cl, const SurfaceIndex& part, const VerifyTool& tool, const VerifyOptions& o,
                       const SurfaceIndex* design) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("verify options: " + why);
  VerifyReport rep;
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
  sweep(part, blocks, o, rep);
  rep.motion = motion_of(blocks);
  if (design) rep.design = design_deviation(*design, blocks, o.gouge_tolerance_mm);
  return rep;
}

}  // namespace flankcam
