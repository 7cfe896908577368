#include "postproc/nc_program.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <optional>

#include "core/errors.h"
#include "core/message_text.h"
#include "postproc/gcode.h"
#include "postproc/tool_export.h"
#include "postproc/verify.h"

namespace flankcam {

const std::vector<DialectInfo>& dialect_table() {
  static const std::vector<DialectInfo> table = {
      {Dialect::Iso, "iso", {"fanuc"}, ".nc", "ISO/Fanuc G-code (G43.4 for TCP, G93 inverse time)"},
      {Dialect::LinuxCnc, "linuxcnc", {}, ".ngc", "LinuxCNC rs274ngc (joints, or tip + angles with trt kinematics)"},
      {Dialect::Heidenhain, "heidenhain", {}, ".h", "Heidenhain conversational (L blocks, M128 for TCP)"},
      {Dialect::Sinumerik, "sinumerik", {}, ".mpf", "Siemens Sinumerik (TRAORI for TCP)"},
  };
  return table;
}

const DialectInfo& dialect_info(Dialect d) {
  for (const DialectInfo& i : dialect_table())
    if (i.dialect == d) return i;
  throw InputError("dialect: not in the table");
}

std::string dialect_names() {
  std::string out;
  for (const DialectInfo& i : dialect_table()) {
    out += (out.empty() ? "" : ", ") + i.name;
    if (!i.aliases.empty()) out += fmt::format(" (or {})", fmt::join(i.aliases, ", "));
  }
  return out;
}

std::string to_string(Dialect d) { return dialect_info(d).name; }

namespace {
const DialectInfo* find_dialect(const std::string& name) {
  for (const DialectInfo& i : dialect_table())
    if (i.name == name || std::find(i.aliases.begin(), i.aliases.end(), name) != i.aliases.end()) return &i;
  return nullptr;
}
}  // namespace

Dialect parse_dialect(const std::string& name) {
  if (const DialectInfo* i = find_dialect(name)) return i->dialect;
  throw InputError(fmt::format("dialect: {} is not one of {}", in_quotes(name), dialect_names()));
}

std::string file_extension(Dialect d) { return dialect_info(d).extension; }

Dialect machine_dialect(const Machine& m) {
  if (const DialectInfo* i = find_dialect(m.controller.dialect)) return i->dialect;
  const std::string where = m.controller.dialect_line > 0 ? fmt::format("{}:{}", m.file, m.controller.dialect_line) : m.file;
  throw MachineError(fmt::format("{}: controller.dialect: {} is not one of {}", where,
                                 in_quotes(m.controller.dialect), dialect_names()));
}

std::string PostOptions::validate() const {
  if (std::string why = path.validate(); !why.empty()) return why;
  if (!(max_inverse_time > 0)) return "max_inverse_time: must be > 0";
  if (!(safe_height_mm >= 0) || !std::isfinite(safe_height_mm)) return "safe_height_mm: must be >= 0";
  if (!(clearance_mm > 0) || !std::isfinite(clearance_mm)) return "clearance_mm: must be > 0";
  if (!(lead_mm > 0) || !std::isfinite(lead_mm)) return "lead_mm: must be > 0";
  if (!(gouge_tolerance_mm > 0) || !std::isfinite(gouge_tolerance_mm)) return "gouge_tolerance_mm: must be > 0";
  if (!(apart.design_gouge_tolerance_mm > 0) || !std::isfinite(apart.design_gouge_tolerance_mm))
    return "design_gouge_tolerance_mm: must be > 0";
  if (!apart.cut_part != !design) return "cut_part and design: give both or neither";
  return {};
}

namespace {

// Which CL move each output pose of a solved path belongs to: the input pose it ends at, or for an
// inserted pose the next input pose (the block it subdivides).
std::vector<int> owners(const JointPath& path) {
  std::vector<int> owner(path.joints.size(), -1);
  int next = -1;
  for (size_t j = path.joints.size(); j-- > 0;) {
    if (path.input_index[j] >= 0) next = path.input_index[j];
    owner[j] = next;
  }
  return owner;
}

bool same_rotaries(const Joints& a, const Joints& b) {
  return std::abs(a.rotary[0] - b.rotary[0]) < 1e-7 && std::abs(a.rotary[1] - b.rotary[1]) < 1e-7;
}

struct Solved {
  ClProgram cl;            // as posted: with a part, its links planned
  JointPath path;
  std::vector<Joints> at;  // programmed values per output pose
  std::vector<int> owner;
  double tool_length_mm = 0;
  ToolAssembly assembly;
};

// The assembly a section is checked with: the given one, or the CL profile alone.
ToolAssembly assembly_of(const PostInput& in) {
  if (!in.assembly.cutter.empty()) return assembly_from_meridian(in.assembly.cutter, in.assembly);
  ToolAssembly a;
  if (in.cl.profile.size() >= 2) return assembly_from_meridian(in.cl.profile, a);
  {  // APT-7 cutter without a profile: its cylinder
    const double r = std::max(0.5 * in.cl.cutter.d, 1e-3), h = in.cl.cutter.h > 0 ? in.cl.cutter.h : 4 * r;
    a.cutter = {{0, r}, {h, r}};
  }
  return a;
}

double max_radius(const ToolAssembly& a) {
  double r = std::max(0.5 * a.shank_diameter, 0.5 * std::max(a.holder_diameter, a.holder_diameter_far));
  for (const auto& c : a.cutter) r = std::max(r, c.y());
  return r;
}

// A move from p to q that only shifts the tool along its own (unchanged) axis: a lead along the axis.
bool axial(const ToolPose& p, const ToolPose& q) {
  const Eigen::Vector3d d = q.tip - p.tip;
  return d.norm() > 1e-9 && p.axis.cross(q.axis).norm() < 1e-9 && p.axis.cross(d).norm() <= 1e-6 * d.norm();
}

// How the back-simulation judges a program posted with `o` (post() checks the emitted text with these
// options); the link planner judges its lead candidates with the same, so that the two agree.
VerifyOptions back_simulation_options(const PostOptions& o) {
  VerifyOptions vo;
  vo.gouge_tolerance_mm = o.gouge_tolerance_mm;
  // Rapids keep the clearance the links were planned with (not merely off the part: the links of a
  // 0.5 mm clearance job came 0.483 mm close); one that does not is planned again farther out.
  vo.link_clearance_mm = o.clearance_mm;
  if (o.design_apart()) vo.apart = o.apart;
  return vo;
}

// The back-simulation as the link planner asks it about one section's leads.
struct LinkJudge {
  const SurfaceIndex& part;
  const SurfaceIndex* design;  // Φ when the cut is judged apart (CutApart), else null
  VerifyTool tool;
  VerifyOptions options;
  Eigen::Vector3d centre;      // of the part's bounding box
  double reach;                // the part's bounding radius plus the assembly's largest radius
};

// A lead's length and the clearance its links keep (mm).
struct LeadDistances {
  double lead_mm, clearance_mm;
};

// Whether the back-simulation passes a lead between the cut pose p and the lead point q: the feed
// along the lead (the cutter within the gouge tolerance, as in the cut; shank and holder `clearance`
// off the part), q as the end of the rapid along the axis, and that rapid out to where the assembly
// is `clearance` beyond the part's bounding ball. The same sweep as the program's back-simulation
// (verify_cl: the tip on a line, the axis held, as the machine moves a lead and the rapid along the
// axis above it): the plan once judged the cutter grown by the clearance with the collision check,
// whose per-slab nearest point missed a blade edge beside the cutter's end that a floor under the tip
// hid (HECC impeller auto-7: 0.121 mm at clearance 0.5 in the back-simulation, then a retry).
// Why a lead candidate is not clear: the first block of its sweep that fails (1: the feed along the
// lead, 2-3: the rapid up the tool axis), the component, and how far it is inside the part (> 0) or
// inside the clearance (<= 0: its distance from the part).
struct LeadMiss {
  int block = 0;
  Component component = Component::Tool;
  double depth_mm = 0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

std::optional<LeadMiss> lead_clear(const LinkJudge& j, const ToolPose& p, const Eigen::Vector3d& q, double clearance) {
  const Eigen::Vector3d axis = p.axis.normalized();
  const double beyond = (q - j.centre).norm() + j.reach + clearance;
  ClProgram cl;
  cl.moves = {{{p.tip, axis}, false, 1}, {{q, axis}, false, 1}, {{q, axis}, true, 0}, {{q + beyond * axis, axis}, true, 0}};
  VerifyOptions vo = j.options;
  vo.link_clearance_mm = clearance;
  const VerifyReport rep = verify_cl(cl, j.part, j.tool, vo, j.design);
  // Block 0 is the cut pose itself, judged with the cut.
  std::optional<LeadMiss> miss;
  for (const VerifyHit& h : rep.hits)
    if (h.block > 0 && (!miss || h.block < miss->block || (h.block == miss->block && h.depth_mm > miss->depth_mm)))
      miss = LeadMiss{h.block, h.component, h.depth_mm, h.point};
  if (miss) return miss;
  const auto& lead = rep.blocks.at(1).min_clearance_mm;
  for (const Component c : {Component::Shank, Component::Holder})
    if (lead[size_t(c)] < clearance) return LeadMiss{1, c, -lead[size_t(c)], p.tip};
  return std::nullopt;
}

// The lead point off pose p, where the rapid along the tool axis from above ends and the lead-in
// begins (the lead-out ends and the retract along the axis begins). Per entry of `levels` in order
// (a retry's doubled distances, then the configured ones), the offsets of lead_offsets: along
// lead_direction, turned about the axis by 20-90 degrees either way, lifted along it by half and a
// whole lead (a hub sloping under the tool's end), then all twice as far out; the first that
// lead_clear passes. A flank in a narrow passage (HECC impeller: the plain lead point's rapid ran
// the cutter 1.7 mm into the part) is entered from the side that is open. None: nullopt (the plain
// point, unchecked, once let a retry's doubled lead-out run 1.9 mm into the impeller's next blade).
// The result of lead_point: the point, or why none is: how many candidates failed in the feed along
// the lead and in the rapid up the axis, and the shallowest of those misses.
struct LeadSearch {
  std::optional<Eigen::Vector3d> point;
  int in_feed = 0, in_rapid = 0;
  std::optional<LeadMiss> least;
  [[nodiscard]] std::string why() const;
};

std::string LeadSearch::why() const {
  if (!least) return {};
  const std::string where = fmt::format("({:.3f}, {:.3f}, {:.3f})", least->point.x(), least->point.y(), least->point.z());
  return fmt::format("{} candidates fail in the feed along the lead, {} in the rapid up the tool axis; the "
                     "nearest miss: the {} {} in the {}",
                     in_feed, in_rapid, to_string(least->component),
                     least->depth_mm > 0 ? fmt::format("{:.3f} mm inside the part at {}", least->depth_mm, where)
                                         : fmt::format("{:.3f} mm from the part", -least->depth_mm),
                     least->block == 1 ? "feed" : "rapid");
}

LeadSearch lead_point(const LinkJudge& j, const ToolPose& p, const std::vector<LeadDistances>& levels) {
  const Eigen::Vector3d axis = p.axis.normalized(), n = lead_direction(j.part, p, j.tool.assembly.cutter_length());
  const std::vector<Eigen::Vector3d> offsets = lead_offsets(n, axis);
  LeadSearch out;
  for (const LeadDistances& d : levels)
    for (const double f : {1.0, 2.0})
      for (const Eigen::Vector3d& offset : offsets) {
        const Eigen::Vector3d q = p.tip + f * d.lead_mm * offset;
        const std::optional<LeadMiss> miss = lead_clear(j, p, q, d.clearance_mm);
        if (!miss) {
          out.point = q;
          return out;
        }
        ++(miss->block == 1 ? out.in_feed : out.in_rapid);
        if (!out.least || miss->depth_mm < out.least->depth_mm) out.least = miss;
      }
  return out;
}

struct PlannedLinks {
  ClProgram cl;
  std::string problem;  // the lead no candidate of lead_point is clear for; "" when planned
};

// The moves of a CL program's cut: from the first feed move (its axial lead-in feeds skipped) to the
// last feed move before its axial lead-out and trailing rapids. None (all rapids): first == size.
std::pair<size_t, size_t> cut_range(const ClProgram& cl) {
  const size_t n = cl.moves.size();
  size_t first = 0;
  while (first < n && cl.moves[first].rapid) ++first;
  if (first == n) return {n, n};
  while (first + 1 < n && !cl.moves[first + 1].rapid && axial(cl.moves[first].pose, cl.moves[first + 1].pose)) ++first;
  size_t last = n - 1;
  while (last > first && cl.moves[last].rapid) --last;
  while (last > first && axial(cl.moves[last - 1].pose, cl.moves[last].pose)) --last;
  return {first, last};
}

// What the planner judges a section's leads with: the back-simulation against `part`, and the lead
// distances to try in order (`o`: this try's, `configured`: the job's; each at least the cutter's
// radius variation plus the clearance: from there a move along the axis cannot reach the finished
// flank of an hourglass tool).
struct LeadPlanner {
  LinkJudge judge;
  std::vector<LeadDistances> levels;
};

LeadPlanner lead_planner(int tool_number, const SurfaceIndex& part, const ToolAssembly& a, const PostOptions& o,
                         const PostOptions& configured) {
  double rmin = INFINITY, rmax = 0;
  for (const auto& c : a.cutter) rmin = std::min(rmin, c.y()), rmax = std::max(rmax, c.y());
  std::vector<LeadDistances> levels;
  for (const PostOptions* x : {&o, &configured}) {
    const LeadDistances d{std::max(x->lead_mm, rmax - rmin + x->clearance_mm), x->clearance_mm};
    if (levels.empty() || d.lead_mm != levels.back().lead_mm || d.clearance_mm != levels.back().clearance_mm) levels.push_back(d);
  }
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& v : part.mesh().vertices) box.extend(v);
  VerifyTool tool;
  tool.number = tool_number, tool.assembly = a;
  return {LinkJudge{part, configured.design_apart(), std::move(tool), back_simulation_options(configured),
                    box.center(), 0.5 * box.diagonal().norm() + max_radius(a)},
          std::move(levels)};
}

// The message of a lead that lead_point found no clear point for.
std::string no_clear_lead(const char* which, size_t k, const ToolPose& pose, const std::vector<LeadDistances>& levels,
                          const LeadSearch& found) {
  return fmt::format("no {} off CL move {} (tip {:.3f}, {:.3f}, {:.3f}) is clear of the part: every direction within 90 "
                     "degrees of the surface normal, lifted by up to a lead, at lead {:g} and {:g} mm, clearance {:g} mm ({})",
                     which, k, pose.tip.x(), pose.tip.y(), pose.tip.z(), levels.back().lead_mm, 2 * levels.back().lead_mm,
                     levels.back().clearance_mm, found.why());
}

// The CL-data with its links planned against the part: its own approach (rapids before the first
// feed move and axial lead-ins) and leave (axial lead-outs and trailing rapids) replaced by a rapid to
// a lead point off the first pose (lead_point), a feed in, the cut, and a feed out to a lead point off
// the last pose. `o`: this try's distances; `configured`: the job's, tried when this try's leave no
// clear lead (a retry doubles them for every section, while one section's link had hit). A lead with
// no clear point keeps the plain one in `cl` and is named in `problem`.
PlannedLinks plan_links(const ClProgram& cl, const SurfaceIndex& part, const ToolAssembly& a, const PostOptions& o,
                        const PostOptions& configured) {
  const auto [first, last] = cut_range(cl);
  if (first == cl.moves.size()) return {cl, {}};
  const LeadPlanner planner = lead_planner(cl.tool, part, a, o, configured);
  PlannedLinks out{cl, {}};
  out.cl.moves.clear();
  const auto lead_at = [&](const ClMove& mv, const size_t k, const char* which) -> Eigen::Vector3d {
    const LeadSearch found = lead_point(planner.judge, mv.pose, planner.levels);
    if (found.point) return *found.point;
    if (out.problem.empty()) out.problem = no_clear_lead(which, k, mv.pose, planner.levels, found);
    return mv.pose.tip + planner.levels.back().lead_mm * lead_direction(part, mv.pose, a.cutter_length());
  };
  const ClMove &p0 = cl.moves[first], &p1 = cl.moves[last];
  out.cl.moves.push_back({{lead_at(p0, first, "lead-in"), p0.pose.axis}, true, 0});
  for (size_t k = first; k <= last; ++k) out.cl.moves.push_back(cl.moves[k]);
  out.cl.moves.back().rapid = false;
  out.cl.moves.push_back({{lead_at(p1, last, "lead-out"), p1.pose.axis}, false, p1.feed_mm_min > 0 ? p1.feed_mm_min : p0.feed_mm_min});
  for (ClMove& mv : out.cl.moves)
    if (!mv.rapid && !(mv.feed_mm_min > 0)) mv.feed_mm_min = p0.feed_mm_min;
  return out;
}

// The part's highest point in the machine frame over the table angles the program uses (a 2 degree
// grid over each table axis' range, plus what a point can rise between grid angles).
// `also`: further rotary angles the program turns to at safe Z (the tool-change position's).
double part_top_machine(const Machine& m, const SurfaceIndex& part, const std::vector<Solved>& solved,
                        const std::array<std::optional<double>, 2>& also) {
  std::array<double, 2> lo{INFINITY, INFINITY}, hi{-INFINITY, -INFINITY};
  for (const Solved& s : solved)
    for (const Joints& q : s.path.joints)
      for (size_t k = 0; k < 2; ++k) lo[k] = std::min(lo[k], q.rotary[k]), hi[k] = std::max(hi[k], q.rotary[k]);
  for (size_t k = 0; k < 2; ++k)
    if (also[k]) lo[k] = std::min(lo[k], *also[k]), hi[k] = std::max(hi[k], *also[k]);
  constexpr double kStepDeg = 2;
  std::array<int, 2> steps{0, 0};
  double reach = 0;
  for (size_t k = 0; k < 2; ++k)
    if (m.rotary[k].carries == Carrier::Table && hi[k] > lo[k]) steps[k] = int(std::ceil((hi[k] - lo[k]) / kStepDeg));
  const auto& verts = part.mesh().vertices;
  for (size_t k = 0; k < 2; ++k)
    if (m.rotary[k].carries == Carrier::Table)
      for (const auto& v : verts) reach = std::max(reach, (v - m.rotary[k].pivot).norm());
  double top = -INFINITY;
  for (int i = 0; i <= steps[0]; ++i)
    for (int j = 0; j <= steps[1]; ++j) {
      std::array<double, 2> deg = {steps[0] ? lo[0] + (hi[0] - lo[0]) * i / steps[0] : lo[0],
                                   steps[1] ? lo[1] + (hi[1] - lo[1]) * j / steps[1] : lo[1]};
      const TableTransform T = table_transform(m, deg);
      const Eigen::RowVector3d row = T.R.row(2);
      for (const auto& v : verts) top = std::max(top, row.dot(v) + T.t.z());
    }
  const int turning = (steps[0] > 0) + (steps[1] > 0);
  return top + turning * reach * (0.5 * kStepDeg * M_PI / 180);
}

// `preposition`: before each tool change but the first, the rotaries and X Y are taken to the machine's
// tool-change position at safe Z, so the change macro only moves Z (its swing happens up there).
// `configured`: the caller's options, `o` this try's (distances doubled on a retry).
Posted post_once(const std::vector<PostInput>& inputs, const Machine& m, const PostOptions& o, const PostOptions& configured,
                 const std::string& name, const std::vector<std::string>& header, bool preposition);

}  // namespace

LeadRange clear_lead_range(const ClProgram& cl, const ToolAssembly& a, const PostOptions& o) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("post options: " + why);
  if (!o.part) throw InputError("clear_lead_range: no part");
  LeadRange r;
  std::tie(r.first, r.last) = cut_range(cl);
  if (r.first == cl.moves.size()) return r;
  r.kept_first = r.first, r.kept_last = r.last;
  const LeadPlanner planner = lead_planner(cl.tool, *o.part, a, o, o);
  const auto search = [&](size_t k) { return lead_point(planner.judge, cl.moves[k].pose, planner.levels); };
  const auto clear = [&](size_t k) { return search(k).point.has_value(); };
  // From an end whose lead is not clear inwards, by steps doubling, to a move whose lead is, then
  // bisected back to the outermost such move between them (where clear and blocked moves alternate a
  // clear one nearer the end may be passed over: the cut is then a little shorter, never unsafe).
  // `inner`: the innermost move that may be kept; `dir`: +1 from the front, -1 from the back.
  const auto outermost_clear = [&](size_t end, size_t inner, long dir) -> std::optional<size_t> {
    long blocked = long(end), ok = -1;
    for (long step = 1;; step *= 2) {
      const long k = std::clamp(long(end) + dir * step, std::min(long(end), long(inner)), std::max(long(end), long(inner)));
      if (k == blocked) return std::nullopt;  // the innermost move reached: no clear lead
      if (clear(size_t(k))) {
        ok = k;
        break;
      }
      blocked = k;
    }
    while (std::abs(ok - blocked) > 1) {
      const long mid = (ok + blocked) / 2;
      (clear(size_t(mid)) ? ok : blocked) = mid;
    }
    return size_t(ok);
  };
  // Each end: kept when its lead is clear, else moved inwards (at least two moves of the cut stay).
  const auto end_of = [&](size_t end, size_t inner, long dir, const char* which) -> std::optional<size_t> {
    const LeadSearch found = search(end);
    if (found.point) return end;
    if (r.why.empty()) r.why = no_clear_lead(which, end, cl.moves[end].pose, planner.levels, found);
    if (dir > 0 ? inner <= end : inner >= end) return std::nullopt;
    return outermost_clear(end, inner, dir);
  };
  const std::optional<size_t> k0 = r.last > r.first ? end_of(r.first, r.last - 1, +1, "lead-in") : std::nullopt;
  const std::optional<size_t> k1 = k0 ? end_of(r.last, *k0 + 1, -1, "lead-out") : std::nullopt;
  if (!k0 || !k1) {
    r.none = true;
    if (r.why.empty()) r.why = "the cut has fewer than two moves";
    return r;
  }
  r.kept_first = *k0, r.kept_last = *k1;
  return r;
}

Posted post(const std::vector<PostInput>& inputs, const Machine& m, const PostOptions& o, const std::string& name,
            const std::vector<std::string>& header) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("post options: " + why);
  if (!o.part) {
    std::vector<std::string> h = header;
    h.push_back("links not checked against the part (no part given): check the program in a simulator");
    Posted p = post_once(inputs, m, o, o, name, h, false);
    p.tolerance_mm = o.path.tolerance_mm;
    p.angle_tolerance_deg = o.path.angle_tolerance_deg;
    return p;
  }
  // Plan, emit, back-simulate the text; when a motion outside the cut hits the part, plan again with
  // the distances doubled (twice at most), else refuse. When the cut alone hits it, linearise finer.
  PostOptions attempt = o;
  bool preposition = false;
  int refined = 0;
  std::string refined_for;
  for (int tries = 0;;) {
    std::vector<std::string> h = header;
    if (refined > 0)
      h.push_back(fmt::format("linearisation refined to {:.6g} mm, {:.6g} deg: at {} mm, {} deg the cut entered the part",
                              attempt.path.tolerance_mm, attempt.path.angle_tolerance_deg, o.path.tolerance_mm,
                              o.path.angle_tolerance_deg));
    Posted p = post_once(inputs, m, attempt, o, name, h, preposition);
    p.tolerance_mm = attempt.path.tolerance_mm;
    p.angle_tolerance_deg = attempt.path.angle_tolerance_deg;
    p.refined = refined;
    p.refined_for = refined_for;
    if (!p.refused.empty()) return p;  // a lead with no clear point: no retry makes room for it
    const std::string text = nc_text(p.program, {o.dialect, o.line_numbers, attempt.path.tolerance_mm});
    std::vector<VerifyTool> tools;
    for (const PostInput& in : inputs)
      if (std::none_of(tools.begin(), tools.end(), [&](const VerifyTool& t) { return t.number == in.cl.tool; }))
        tools.push_back({in.cl.tool, assembly_of(in), in.tool_length_mm > 0 ? in.tool_length_mm : o.path.tool_length_mm});
    const VerifyReport rep = verify_text(text, o.dialect, name + file_extension(o.dialect), m, *o.part, tools,
                                         back_simulation_options(o), o.design_apart());
    const bool links_clear = std::none_of(rep.hits.begin(), rep.hits.end(), [](const VerifyHit& h) { return h.rapid; });
    const bool cut_only = !rep.hits.empty() && rep.cl_deviations.empty() &&
                          std::all_of(rep.hits.begin(), rep.hits.end(), [](const VerifyHit& h) {
                            return !h.rapid && !h.tool_change && h.component == Component::Tool;
                          });
    if (cut_only && refined < Posted::kMaxRefinements) {
      if (refined == 0) refined_for = rep.first_problem(name + file_extension(o.dialect));
      ++refined;
      attempt.path.tolerance_mm /= 2;
      attempt.path.angle_tolerance_deg /= 2;
      continue;
    }
    if (links_clear || tries >= 2) {
      p.links_checked = true;
      for (const VerifiedBlock& b : rep.blocks)
        if (b.rapid)
          for (double c : b.min_clearance_mm) p.min_link_clearance_mm = std::min(p.min_link_clearance_mm, c);
      if (!rep.clean()) {
        p.refused = "back-simulation: " + rep.first_problem(name + file_extension(o.dialect));
        if (refined > 0)
          p.refused += fmt::format(" (linearised down to {:.6g} mm, {:.6g} deg)", attempt.path.tolerance_mm,
                                   attempt.path.angle_tolerance_deg);
        p.worst_line = rep.hits.front().line;
        for (const VerifyHit& h : rep.hits) p.worst_line = std::min(p.worst_line, h.line);
      }
      return p;
    }
    ++tries;
    // A tool change that hits the part: its swing moves up to safe Z first.
    if (!preposition && std::any_of(rep.hits.begin(), rep.hits.end(), [](const VerifyHit& h) { return h.tool_change; })) {
      preposition = true;
      continue;
    }
    attempt.safe_height_mm = 2 * attempt.safe_height_mm + attempt.clearance_mm;
    attempt.lead_mm *= 2;
    attempt.clearance_mm *= 2;
  }
}

namespace {

Posted post_once(const std::vector<PostInput>& inputs, const Machine& m, const PostOptions& o, const PostOptions& configured,
                 const std::string& name, const std::vector<std::string>& header, bool preposition) {
  if (inputs.empty()) throw InputError("post: no CL-data");
  const bool tcp = m.controller.tcp || m.controller.linuxcnc_trt;
  // LinuxCNC's trt kinematics turns two table axes; a head axis needs the controller's own TCP.
  if (m.controller.linuxcnc_trt && m.tables() != 2)
    throw MachineError(fmt::format("{}: controller.linuxcnc_trt: LinuxCNC's trt kinematics is for two table axes, and {} "
                                   "is a {} machine",
                                   m.file, m.name, m.kind()));
  if (o.dialect == Dialect::LinuxCnc && m.controller.tcp && !m.controller.linuxcnc_trt)
    throw InputError(
        m.tables() == 2
            ? fmt::format("post.dialects: linuxcnc: LinuxCNC has no G43.4 and {} is programmed with TCP; choose another "
                          "dialect, or set controller.linuxcnc_trt when LinuxCNC's trt kinematics is active",
                          m.name)
            : fmt::format("post.dialects: linuxcnc: LinuxCNC has no G43.4 and {} ({}) turns its head under TCP; choose "
                          "iso, heidenhain or sinumerik",
                          m.name, m.kind()));

  // Kinematics of every section first: the safe height depends on all of them.
  std::vector<Solved> solved;
  std::string refused;  // the first lead the planner found no clear point for
  double top_z = -INFINITY;
  for (const PostInput& in : inputs) {
    if (in.cl.moves.empty()) throw InputError(fmt::format("patch '{}': the CL-data has no GOTO", in.patch));
    for (size_t k = 0; k < in.cl.moves.size(); ++k)
      if (!in.cl.moves[k].rapid && !(in.cl.moves[k].feed_mm_min > 0))
        throw InputError(fmt::format("patch '{}': CL move {} is a feed move without a feed rate (FEDRAT)", in.patch, k));
    Solved s;
    s.assembly = assembly_of(in);
    if (std::string why = s.assembly.validate(); !why.empty()) throw InputError(fmt::format("patch '{}': {}", in.patch, why));
    s.cl = in.cl;
    if (o.part) {
      PlannedLinks planned = plan_links(in.cl, *o.part, s.assembly, o, configured);
      s.cl = std::move(planned.cl);
      if (!planned.problem.empty() && refused.empty()) refused = fmt::format("link planning: patch '{}': {}", in.patch, planned.problem);
    }
    std::vector<ToolPose> poses;
    for (const ClMove& mv : s.cl.moves) poses.push_back(mv.pose);
    PathOptions po = o.path;
    if (in.tool_length_mm > 0) po.tool_length_mm = in.tool_length_mm;
    s.tool_length_mm = po.tool_length_mm;
    s.path = solve_path(m, poses, {}, po);
    require_reachable(s.path, poses, in.patch);
    s.owner = owners(s.path);
    for (size_t j = 0; j < s.path.joints.size(); ++j) {
      s.at.push_back(programmed(m, s.path.joints[j], s.path.poses[j]));
      top_z = std::max(top_z, s.at.back().linear.z());
    }
    solved.push_back(std::move(s));
  }

  Posted out;
  out.refused = refused;
  NcProgram& p = out.program;
  p.name = name;
  p.header = header;
  if (o.dialect == Dialect::LinuxCnc && m.controller.linuxcnc_trt)
    p.header.push_back("tip + angles: LinuxCNC's trt kinematics (trtkins) must be active");
  p.machine = m.name;
  p.rotary_names = {m.rotary[0].name, m.rotary[1].name};
  p.tcp = tcp;
  p.inverse_time = m.controller.inverse_time && o.dialect != Dialect::Heidenhain;
  if (o.part) {
    // Above the part placed on the machine, over every table angle the program turns through; a
    // tilted head lowers the assembly's side by up to its largest radius. The controlled point (Z
    // joint, or the tip under TCP with a vertical table axis) is the tip's height.
    double r = 0;
    for (const Solved& s : solved) r = std::max(r, max_radius(s.assembly));
    int tools = 0;
    for (size_t i = 0; i < inputs.size(); ++i) tools += i == 0 || inputs[i].cl.tool != inputs[i - 1].cl.tool;
    std::array<std::optional<double>, 2> also;
    if (preposition && tools > 1) also = {m.tool_change.joints[3], m.tool_change.joints[4]};
    p.safe_z = part_top_machine(m, *o.part, solved, also) + std::max(o.safe_height_mm, o.clearance_mm) + (m.tables() < 2 ? r : 0);
  } else {
    // Joint values cannot go above the Z travel; the program's own highest point is below it.
    p.safe_z = top_z + o.safe_height_mm;
    if (!tcp) p.safe_z = std::max(top_z, std::min(p.safe_z, m.linear[2].max_mm));
  }
  // Under TCP with a part, the moves between safe Z and the cut follow the tool axis (a tilted tool
  // moved vertically drags its side through the part): the point on the axis line at safe Z.
  const bool along_axis = tcp && o.part;
  const auto on_axis_at_safe_z = [&](const Joints& at, double tool_length) {
    const ToolPose pose = programmed_pose(m, at, tool_length);
    Joints up = at;
    if (pose.axis.z() > 0.2) up.linear = at.linear + std::max(0.0, (p.safe_z - at.linear.z()) / pose.axis.z()) * pose.axis;
    up.linear.z() = p.safe_z;
    return up;
  };

  int tool = -1;
  bool have_position = false;
  Joints current;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const PostInput& in = inputs[i];
    const Solved& s = solved[i];
    PostedSection sec;
    sec.patch = in.patch;
    auto add_move = [&](bool rapid, unsigned axes, const Joints& at, const ToolPose& pose, int cl_move) {
      NcMove mv;
      mv.rapid = rapid;
      mv.axes = axes;
      mv.at = at;
      mv.pose = pose;
      mv.cl_move = cl_move;
      p.blocks.push_back(mv);
      current = at;
    };
    sec.first_block = int(p.blocks.size());
    p.blocks.push_back(NcComment{"patch " + in.patch});
    for (const std::string& c : in.cl.comments) p.blocks.push_back(NcComment{c});
    if (in.cl.tool != tool) {
      if (preposition && tool >= 0 && have_position) {
        // To the tool-change position's rotaries, then its X Y, at safe Z (in machine joints; under TCP
        // the tip that puts them there).
        const double L = solved[i - 1].tool_length_mm;
        const auto& tc = m.tool_change.joints;
        Joints j = tcp ? Joints{linear_joints(m, programmed_pose(m, current, L), current.rotary, L), current.rotary} : current;
        const auto program_at = [&](const Joints& q) { return tcp ? Joints{forward(m, q, L).tip, q.rotary} : q; };
        if (tc[3] || tc[4]) {
          Joints at = current;  // under TCP the tip is held while the rotaries turn
          for (size_t k = 0; k < 2; ++k)
            if (tc[3 + k]) at.rotary[k] = *tc[3 + k];
          add_move(true, AxesRotary, at, programmed_pose(m, at, L), -1);
          j = tcp ? Joints{linear_joints(m, programmed_pose(m, current, L), current.rotary, L), current.rotary} : current;
        }
        if (tc[0] || tc[1]) {
          for (size_t k = 0; k < 2; ++k)
            if (tc[k]) j.linear[k] = *tc[k];
          const Joints at = program_at(j);
          add_move(true, AxisX | AxisY, at, programmed_pose(m, at, L), -1);
        }
      }
      tool = in.cl.tool;
      const ToolDimensions dim = tool_dimensions(in.cl.profile);
      // L: the length the program is posted with (spindle nose to tip on head machines), else the cutter's.
      p.blocks.push_back(NcToolChange{tool, in.cl.partno, dim.diameter_max_mm,
                                      s.tool_length_mm > 0 && m.tables() < 2 ? s.tool_length_mm : dim.length_mm});
      have_position = false;  // after a tool change the spindle may be anywhere: approach from safe Z
    }
    p.blocks.push_back(NcSpindle{in.cl.spindle_rpm, in.cl.clockwise});
    p.blocks.push_back(NcCoolant{in.cl.coolant});
    const ClProgram& cl = s.cl;

    // Feeds per output block: the CL move's feed; rapids get a nominal one (their F is not written).
    std::vector<double> feed(s.path.joints.size(), 1.0);
    for (size_t j = 1; j < feed.size(); ++j) {
      const ClMove& mv = cl.moves[size_t(s.owner[j])];
      if (!mv.rapid) feed[j] = mv.feed_mm_min;
    }
    const std::vector<BlockFeed> bf = block_feeds(m, s.path, feed);

    size_t j = 0;
    for (size_t k = 0; k < cl.moves.size(); ++k) {
      // Output poses j..jk end in CL move k (jk is the input pose itself).
      size_t jk = j;
      while (s.path.input_index[jk] != int(k)) ++jk;
      const ClMove& mv = cl.moves[k];
      const Joints& target = s.at[jk];
      if (mv.rapid || !have_position) {
        if (!have_position || !same_rotaries(current, target)) {
          // Safe approach: up to safe Z, turn the rotaries, over to X Y, down to the target.
          if (along_axis) {
            const Joints above = on_axis_at_safe_z(target, s.tool_length_mm);
            Joints up = have_position ? on_axis_at_safe_z(current, s.tool_length_mm) : above;
            if (have_position && (up.linear - current.linear).norm() > 1e-9)
              add_move(true, AxesLinear, up, programmed_pose(m, up, s.tool_length_mm), -1);
            else if (!have_position)
              add_move(true, AxisZ, up, programmed_pose(m, up, s.tool_length_mm), -1);
            up.rotary = target.rotary;
            add_move(true, AxesRotary, up, programmed_pose(m, up, s.tool_length_mm), -1);
            add_move(true, AxisX | AxisY, above, programmed_pose(m, above, s.tool_length_mm), -1);
          } else {
            Joints up = have_position ? current : target;
            up.linear.z() = p.safe_z;
            add_move(true, AxisZ, up, programmed_pose(m, up, s.tool_length_mm), -1);
            up.rotary = target.rotary;
            add_move(true, AxesRotary, up, programmed_pose(m, up, s.tool_length_mm), -1);
            up.linear.x() = target.linear.x(), up.linear.y() = target.linear.y();
            add_move(true, AxisX | AxisY, up, programmed_pose(m, up, s.tool_length_mm), -1);
          }
        }
        add_move(true, AxesLinear, target, s.path.poses[jk], int(k));
        have_position = true;
      } else {
        for (size_t q = j; q <= jk; ++q) {
          const BlockFeed& b = bf[q];
          double minutes = b.minutes;
          bool slowed = b.limiting_axis >= 0;
          if (1 / minutes > o.max_inverse_time) minutes = 1 / o.max_inverse_time, slowed = true;
          sec.slowed_blocks += slowed;
          NcMove nm;
          nm.rapid = false;
          nm.axes = AxesAll;
          nm.at = s.at[q];
          nm.pose = s.path.poses[q];
          nm.cl_move = q == jk ? int(k) : -1;
          nm.inverse_time = 1 / minutes;
          // G94: F is the path feed of the programmed linear axes, or deg/min for a rotary-only block.
          const Joints& a = q > 0 ? s.at[q - 1] : current;
          double dist = (nm.at.linear - a.linear).norm();
          if (dist < 1e-6) dist = std::hypot(nm.at.rotary[0] - a.rotary[0], nm.at.rotary[1] - a.rotary[1]);
          nm.feed_mm_min = dist > 0 ? dist / minutes : feed[q];
          p.blocks.push_back(nm);
          current = nm.at;
        }
      }
      j = jk + 1;
    }
    // Retract to safe Z (under TCP with a part: along the tool): the next section (or the end) starts there.
    Joints up = current;
    up.linear.z() = p.safe_z;
    if (along_axis) up = on_axis_at_safe_z(current, s.tool_length_mm);
    add_move(true, along_axis ? unsigned(AxesLinear) : unsigned(AxisZ), up, programmed_pose(m, up, s.tool_length_mm), -1);
    sec.cl = s.cl;
    sec.path = s.path;
    sec.end_block = int(p.blocks.size());
    out.sections.push_back(std::move(sec));
  }
  p.blocks.push_back(NcSpindle{0, true});
  p.blocks.push_back(NcCoolant{false});
  return out;
}

}  // namespace

}  // namespace flankcam
