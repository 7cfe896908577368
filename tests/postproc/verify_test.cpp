#include "postproc/verify.h"

#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <regex>
#include <sstream>

#include "core/check_surface.h"
#include "core/errors.h"
#include "kinematics/machine.h"
#include "postproc/gcode.h"
#include "postproc/nc_program.h"
#include "tests/postproc/wall.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

Machine shipped_machine(const std::string& name) { return load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml"); }

// The wall of a tool with meridian r moving along y (y in [-40, 40]).
TriMesh wall(const std::function<double(double)>& r) { return test::flank_wall(r, 40, 80, 40); }

std::vector<Eigen::Vector2d> meridian(const std::function<double(double)>& r) {
  std::vector<Eigen::Vector2d> out;
  for (int k = 0; k <= 40; ++k) out.emplace_back(25.0 * k / 40, r(25.0 * k / 40));
  return out;
}

double cone(double z) { return 3 + 0.1 * z; }
double hourglass(double z) { return 4 - 1.0 * std::sin(M_PI * z / 25); }

// The flank pass along the wall (placed in the work frame at `origin`), with the CL-data's own axial
// lead-in and leave as flank_program writes them.
ClProgram pass(const std::function<double(double)>& r, const Eigen::Vector3d& origin) {
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 20; ++i) poses.push_back({origin + Eigen::Vector3d(0, -20 + 2.0 * i, 0), Eigen::Vector3d::UnitZ()});
  return flank_program("WALL", poses, meridian(r), 600, 10000, 5, 30);
}

TriMesh moved(TriMesh m, const Eigen::Vector3d& by) {
  for (auto& v : m.vertices) v += by;
  return m;
}

ToolAssembly holder() {
  ToolAssembly a;
  a.shank_length = 10, a.shank_diameter = 8;
  a.holder_length = 20, a.holder_diameter = 20, a.holder_diameter_far = 30;
  return a;
}

struct VerifyCase {
  std::string label;
  Machine machine;
  Dialect dialect;
};
std::vector<VerifyCase> verify_cases() {
  return {{"xyzac-trt", shipped_machine("xyzac-trt"), Dialect::LinuxCnc},
          {"xyzbc-trt", shipped_machine("xyzbc-trt"), Dialect::Iso},
          {"xyzbc-trt-sinumerik", shipped_machine("xyzbc-trt"), Dialect::Sinumerik},
          {"xyzbc-head-table", shipped_machine("xyzbc-head-table"), Dialect::Iso},
          {"xyzca-head-head", shipped_machine("xyzca-head-head"), Dialect::Heidenhain},
          {"xyzbc-nutating", shipped_machine("xyzbc-nutating"), Dialect::Sinumerik}};
}

struct Posting {
  Posted posted;
  std::string text;
  std::vector<VerifyTool> tools;
};
Posting post_wall(const VerifyCase& c, const SurfaceIndex& part, const std::function<double(double)>& r, const Eigen::Vector3d& origin,
                  double clearance_mm = PostOptions{}.clearance_mm) {
  PostOptions o;
  o.clearance_mm = clearance_mm;
  o.dialect = c.dialect;
  o.path.tool_length_mm = 80;
  o.part = &part;
  o.gouge_tolerance_mm = 0.01;
  PostInput in{pass(r, origin), "wall", 80, assembly_from_meridian(meridian(r), holder())};
  Posting p;
  p.posted = post({in}, c.machine, o, "WALL", {"verify test"});
  p.text = nc_text(p.posted.program, {c.dialect, false, o.path.tolerance_mm});
  p.tools = {{1, in.assembly, 80}};
  return p;
}

// The text with line `line` (1-based) replaced.
std::string with_line(const std::string& text, int line, const std::string& replacement) {
  std::istringstream in(text);
  std::string out, l;
  for (int n = 1; std::getline(in, l); ++n) out += (n == line ? replacement : l) + "\n";
  return out;
}
std::string line_of(const std::string& text, int line) {
  std::istringstream in(text);
  std::string l;
  for (int n = 1; std::getline(in, l); ++n)
    if (n == line) return l;
  return {};
}

// The line of the k-th feed block in the middle of the cut (lines with a feed word).
int cutting_line(const std::string& text, const std::vector<NcPoint>& pts) {
  std::vector<int> feeds;
  for (const NcPoint& p : pts)
    if (!p.rapid) feeds.push_back(p.line);
  REQUIRE(feeds.size() > 4);
  (void)text;
  return feeds[feeds.size() / 2];
}

// Lowers the Z word of a line by 1 mm (G-code "Z12.3456", Heidenhain "Z+12.3456").
std::string lower_z(const std::string& line) {
  const std::regex z(R"(Z([+-]?)(\d+\.\d+))");
  std::smatch m;
  REQUIRE(std::regex_search(line, m, z));
  const double v = std::stod(m[1].str() + m[2].str()) - 1;
  char buf[64];
  std::snprintf(buf, sizeof buf, "Z%s%.4f", v >= 0 && !m[1].str().empty() ? "+" : "", v);
  return m.prefix().str() + buf + m.suffix().str();
}

}  // namespace

TEST_CASE("every shipped machine and dialect: the posted wall pass back-simulates clean, links clear of the part" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cone), origin));
  for (const VerifyCase& c : verify_cases()) {
    CAPTURE(c.label);
    const Posting p = post_wall(c, part, cone, origin);
    CHECK(p.posted.links_checked);
    CHECK(p.posted.refused.empty());
    MESSAGE(c.label << ": min link clearance " << p.posted.min_link_clearance_mm << " mm, safe Z " << p.posted.program.safe_z);
    // The links keep the clearance they were planned with (PostOptions' default, 1 mm), not merely
    // off the part; with 6 mm too.
    CHECK(p.posted.min_link_clearance_mm >= PostOptions{}.clearance_mm);
    const Posting wide = post_wall(c, part, cone, origin, 6);
    MESSAGE(c.label << ": min link clearance " << wide.posted.min_link_clearance_mm << " mm at a 6 mm clearance");
    CHECK(wide.posted.refused.empty());
    CHECK(wide.posted.min_link_clearance_mm >= 6);
    // Safe Z is above the part's top (z = 15 here; the tables turn it in the machine frame).
    CHECK(p.posted.program.safe_z > 15);
    const VerifyReport rep = verify_text(p.text, c.dialect, "wall", c.machine, part, p.tools, {});
    CHECK(rep.clean());
    CHECK(rep.violations.empty());
    CHECK(rep.cut_minutes > 0);
    CHECK(rep.cycle_minutes > rep.cut_minutes);
    // The cut touches the wall: the cutter's clearance in the feed blocks is within the tolerance of 0.
    double feed_min = INFINITY, rapid_min = INFINITY;
    for (const VerifiedBlock& b : rep.blocks) (b.rapid ? rapid_min : feed_min) = std::min(b.rapid ? rapid_min : feed_min, b.min_clearance_mm[0]);
    CHECK(std::abs(feed_min) < 0.011);
    CHECK(rapid_min > 0);
  }
}

TEST_CASE("a cutting block with Z lowered by 1 mm is a gouge on exactly that line, in every dialect" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cone), origin));
  for (const VerifyCase& c : verify_cases()) {
    CAPTURE(c.label);
    const Posting p = post_wall(c, part, cone, origin);
    const std::vector<NcPoint> pts = parse_nc(p.text, c.dialect, p.posted.program.rotary_names, "wall");
    const int line = cutting_line(p.text, pts);
    const std::string edited = with_line(p.text, line, lower_z(line_of(p.text, line)));
    const VerifyReport rep = verify_text(edited, c.dialect, "wall", c.machine, part, p.tools, {});
    REQUIRE_FALSE(rep.clean());
    // The lowered block and the one after it (which climbs back) are the only ones that cut too deep.
    for (const VerifyHit& h : rep.hits) {
      CHECK(h.component == Component::Tool);
      CHECK(h.kind() == "gouge");
      CHECK(h.depth_mm > 0.05);  // cone r' = 0.1: 1 mm lower is ~0.1 mm deeper
      CHECK(h.depth_mm < 0.11);
      const bool here = h.line == line || h.line == pts[size_t(std::find_if(pts.begin(), pts.end(), [&](const NcPoint& q) { return q.line == line; }) - pts.begin()) + 1].line;
      CHECK(here);
    }
    CHECK(rep.first_problem("wall").rfind("wall:" + std::to_string(line) + ":", 0) == 0);
  }
}

TEST_CASE("a rapid through the part is a collision on its line") {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cone), origin));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const Posting p = post_wall(c, part, cone, origin);
  const std::vector<NcPoint> pts = parse_nc(p.text, c.dialect, p.posted.program.rotary_names, "wall");
  // Replace the first lead-in feed block's line by a rapid that crosses the wall (x + 20).
  const int line = cutting_line(p.text, pts);
  const NcPoint& at = *std::find_if(pts.begin(), pts.end(), [&](const NcPoint& q) { return q.line == line; });
  char buf[128];
  std::snprintf(buf, sizeof buf, "G0 X%.4f Y%.4f Z%.4f", at.at.linear.x() + 20, at.at.linear.y(), at.at.linear.z());
  const std::string edited = with_line(p.text, line, buf);
  const VerifyReport rep = verify_text(edited, c.dialect, "wall", c.machine, part, p.tools, {});
  REQUIRE_FALSE(rep.clean());
  bool found = false;
  for (const VerifyHit& h : rep.hits)
    if (h.line == line && h.rapid && h.kind() == "collision") found = true;
  CHECK(found);
  MESSAGE("rapid through the wall: " << rep.first_problem("wall"));
}

TEST_CASE("a rapid off the part but inside the rapid clearance is a finding of its own, with its distance") {
  // The cone's rapid along its wall (tip radius 3, widening 0.1 per mm: the wall x = 3 + 0.1 z), the
  // axis upright, `offset` mm from the cut in x: |offset| / sqrt(1.01) from the wall, inside it for
  // offset > 0. Before, verify --job judged rapids against no clearance: a plunge 0.020 mm from the
  // HECC impeller's part in a program of a 0.5 mm job was "clean".
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cone), origin));
  const VerifyTool tool{1, assembly_from_meridian(meridian(cone), holder()), 80};
  const auto rapid_at = [&](double offset) {
    ClProgram cl;
    cl.tool = 1;
    for (const double y : {-20.0, 20.0})
      cl.moves.push_back({{origin + Eigen::Vector3d(offset, y, 0), Eigen::Vector3d::UnitZ()}, true, 0});
    return cl;
  };
  const double off = 0.3 / std::sqrt(1.01);
  VerifyOptions o;
  o.link_clearance_mm = 0.5;
  const VerifyReport near = verify_cl(rapid_at(-0.3), part, tool, o);
  REQUIRE(near.hits.size() == 2);  // the rapid to its start and the one along the wall (blocks 0 and 1)
  for (const VerifyHit& h : near.hits) {
    CHECK(h.rapid);
    CHECK(h.component == Component::Tool);
    CHECK(h.kind() == "clearance");
    CHECK(-h.depth_mm == doctest::Approx(off).epsilon(0.01));
  }
  CHECK(near.blocks.at(1).min_clearance_mm[0] == doctest::Approx(off).epsilon(0.01));
  const std::string problem = near.first_problem("near.apt");
  MESSAGE(problem);
  CHECK(problem.rfind(fmt::format("near.apt:1: tool {:.4f} mm from the part, inside the rapid clearance of 0.5 mm at (",
                                  -near.hits.front().depth_mm),
                      0) == 0);
  // Judged against a clearance it keeps: clean, its clearance reported.
  o.link_clearance_mm = 0.25;
  const VerifyReport kept = verify_cl(rapid_at(-0.3), part, tool, o);
  CHECK(kept.clean());
  CHECK(kept.blocks.at(1).min_clearance_mm[0] == doctest::Approx(off).epsilon(0.01));
  // Into the wall: a collision, whatever the clearance.
  for (const double c : {0.0, 0.5}) {
    o.link_clearance_mm = c;
    const VerifyReport into = verify_cl(rapid_at(0.3), part, tool, o);
    REQUIRE(into.hits.size() == 2);
    for (const VerifyHit& h : into.hits) {
      CHECK(h.kind() == "collision");
      CHECK(h.depth_mm == doctest::Approx(off).epsilon(0.01));
    }
    const std::string expected = fmt::format("into.apt:1: tool collision {:.4f} mm deep at (", into.hits.front().depth_mm);
    CHECK(into.first_problem("into.apt").rfind(expected, 0) == 0);
  }
}

TEST_CASE("hourglass tool: the CL-data's axial lead-in gouges the finished flank, the planned normal lead does not" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(hourglass), origin));
  const VerifyTool tool{1, assembly_from_meridian(meridian(hourglass), holder()), 80};
  // The CL-data as flank_program writes it: feed in 5 mm along the axis.
  const VerifyReport axial = verify_cl(pass(hourglass, origin), part, tool, {});
  REQUIRE_FALSE(axial.clean());
  double deepest = 0;
  for (const VerifyHit& h : axial.hits) deepest = std::max(deepest, h.depth_mm);
  MESSAGE("axial lead-in of an hourglass tool: " << axial.first_problem("wall.apt"));
  CHECK(deepest > 0.1);
  for (const VerifyCase& c : verify_cases()) {
    CAPTURE(c.label);
    const Posting p = post_wall(c, part, hourglass, origin);
    CHECK(p.posted.refused.empty());
    const VerifyReport rep = verify_text(p.text, c.dialect, "wall", c.machine, part, p.tools, {});
    CHECK(rep.clean());
  }
}

TEST_CASE("a ledge rising into the flat end under the rim is a gouge, though the part's nearest point lies under the tip") {
  // The cone pass along its wall (tip radius 3 at z = 0); for y >= 0 (of the pass' y -20..20) a face
  // from the wall's foot (3, y, rise) down to the axis (0, y, -1). The part point nearest to the tip's
  // axis point lies below the tip plane, outside the tool; the face enters the end face under the
  // rim next to the wall, at most 3 rise / (4 + rise) deep (the cone a little more). Before, the
  // back-simulation measured the 1 mm rise 0.154 mm deep and passed the 0.3 mm rise and every lower
  // one; now each is found, measured at the part point it found (0.6 of that depth or more here).
  const Eigen::Vector3d origin(30, 10, -5);
  const VerifyTool tool{1, assembly_from_meridian(meridian(cone), holder()), 80};
  for (const double rise : {1.0, 0.3, 0.2, 0.1, 0.05, -0.1}) {
    const TriMesh ledge = test::grid_mesh(2, 21, [&](int i, int j) { return Eigen::Vector3d(3.0 - 3.0 * i, 1.0 * j, i ? -1.0 : rise); });
    const SurfaceIndex part(moved(test::merged(wall(cone), ledge), origin));
    const VerifyReport rep = verify_cl(pass(cone, origin), part, tool, {});
    double deepest = 0;
    for (const VerifyHit& h : rep.hits)
      if (h.component == Component::Tool && !h.rapid) deepest = std::max(deepest, h.depth_mm);
    const double expected = 3 * rise / (4 + rise);
    MESSAGE("rise " << rise << " mm: " << rep.hits.size() << " hits, " << deepest << " mm deep of " << expected);
    if (rise < 0) {
      CHECK(rep.clean());
      continue;
    }
    REQUIRE_FALSE(rep.clean());
    CHECK(deepest > 0.55 * expected);
    CHECK(deepest < 1.1 * expected + 0.01);  // the cone widens 0.1 mm per mm above its tip
  }
}

TEST_CASE("the machined design surface: the wall is reached and within tolerance where the pass runs") {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cone), origin));
  const VerifyCase c = verify_cases()[1];
  const Posting p = post_wall(c, part, cone, origin);
  const VerifyReport rep = verify_text(p.text, c.dialect, "wall", c.machine, part, p.tools, {}, &part);
  CHECK(rep.design.reached > 0);
  // The pass runs y in [-20, 20] of the wall's [-40, 40] (work y in [-10, 30]): the far ends are not reached.
  CHECK(rep.design.reached < int(part.mesh().vertices.size()));
  int inside = 0;
  for (size_t v = 0; v < part.mesh().vertices.size(); ++v) {
    const Eigen::Vector3d& x = part.mesh().vertices[v];
    if (x.y() < -5 || x.y() > 25 || x.z() < -4.5 || x.z() > 14.5) continue;  // well inside the swept strip
    ++inside;
    CHECK(std::abs(rep.design.deviation_mm[v]) <= 0.01);
  }
  CHECK(inside > 500);
  MESSAGE("design coverage " << rep.design.coverage() << " of " << rep.design.reached << " reached vertices");
}

TEST_CASE("post without a part says that links were not checked, and refusals name the key") {
  const VerifyCase c = verify_cases()[1];
  PostOptions o;
  o.dialect = c.dialect;
  const Posted p = post({{pass(cone, Eigen::Vector3d(30, 10, -5)), "wall", 0, {}}}, c.machine, o, "WALL", {});
  CHECK_FALSE(p.links_checked);
  const bool said = std::any_of(p.program.header.begin(), p.program.header.end(),
                                [](const std::string& h) { return h.find("not checked") != std::string::npos; });
  CHECK(said);
  // LinuxCNC on a head machine under TCP: names post.dialects and does not suggest linuxcnc_trt.
  o.dialect = Dialect::LinuxCnc;
  o.path.tool_length_mm = 80;
  try {
    (void)post({{pass(cone, Eigen::Vector3d(30, 10, -5)), "wall", 0, {}}}, shipped_machine("xyzbc-head-table"), o, "WALL", {});
    FAIL("linuxcnc on a TCP head machine was accepted");
  } catch (const InputError& e) {
    const std::string what = e.what();
    CHECK(what.find("post.dialects") != std::string::npos);
    CHECK(what.find("linuxcnc_trt") == std::string::npos);
  }
  // linuxcnc_trt on a head machine is refused.
  Machine head = shipped_machine("xyzbc-head-table");
  head.controller.linuxcnc_trt = true;
  CHECK_THROWS_AS((void)post({{pass(cone, Eigen::Vector3d(30, 10, -5)), "wall", 0, {}}}, head, o, "WALL", {}), MachineError);
}

TEST_CASE("the tool-change comment gives the length the program is posted with") {
  PostOptions o;
  o.dialect = Dialect::Iso;
  o.path.tool_length_mm = 122.109;
  const Posted head = post({{pass(cone, Eigen::Vector3d(30, 10, -5)), "wall", 0, {}}}, shipped_machine("xyzbc-head-table"), o, "W", {});
  const std::string text = nc_text(head.program, {Dialect::Iso, false, 0.005});
  CHECK(text.find(" L122.109)") != std::string::npos);
  // Table-table: the tool length does not enter the kinematics; the comment keeps the cutter's (25 mm).
  const Posted trt = post({{pass(cone, Eigen::Vector3d(30, 10, -5)), "wall", 0, {}}}, shipped_machine("xyzbc-trt"), o, "W", {});
  CHECK(nc_text(trt.program, {Dialect::Iso, false, 0.005}).find(" L25.000)") != std::string::npos);
}

namespace {
double cylinder(double) { return 4; }

// The wall pass's CL-data in the work frame, as verify loads NAME.apt beside a program.
std::vector<ClReference> wall_cl(const std::function<double(double)>& r, const Eigen::Vector3d& origin) {
  return {{0, pass(r, origin), "wall.apt"}};
}
}  // namespace

TEST_CASE("every shipped machine and dialect: the posted wall pass lies on its CL-data, the planned leads excepted" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cylinder), origin));
  for (const VerifyCase& c : verify_cases()) {
    CAPTURE(c.label);
    const Posting p = post_wall(c, part, cylinder, origin);
    const VerifyReport rep = verify_text(p.text, c.dialect, "wall", c.machine, part, p.tools, {}, nullptr, wall_cl(cylinder, origin));
    CHECK(rep.cl_compared);
    CHECK(rep.cl_deviations.empty());
    CHECK(rep.clean());
    // 20 CL feed moves plus the lead-in and lead-out along the normal (joints may add blocks).
    CHECK(rep.cl_blocks >= 22);
    CHECK(rep.cl_max_deviation_mm <= 0.007);
  }
}

TEST_CASE("a cylinder's cutting block lowered 1 mm along its axis cuts nothing new, and is named by the CL comparison" * doctest::test_suite("heavy")) {
  // The tool slides along its own axis: the geometric sweep cannot see it, the CL-data can.
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cylinder), origin));
  for (const VerifyCase& c : verify_cases()) {
    CAPTURE(c.label);
    const Posting p = post_wall(c, part, cylinder, origin);
    const std::vector<NcPoint> pts = parse_nc(p.text, c.dialect, p.posted.program.rotary_names, "wall");
    const int line = cutting_line(p.text, pts);
    const std::string edited = with_line(p.text, line, lower_z(line_of(p.text, line)));
    const VerifyReport geometric = verify_text(edited, c.dialect, "wall", c.machine, part, p.tools, {});
    CHECK(geometric.hits.empty());
    CHECK(geometric.clean());
    const VerifyReport rep = verify_text(edited, c.dialect, "wall", c.machine, part, p.tools, {}, nullptr, wall_cl(cylinder, origin));
    CHECK(rep.hits.empty());
    REQUIRE_FALSE(rep.cl_deviations.empty());
    CHECK(rep.cl_deviations.front().line == line);
    CHECK(rep.cl_deviations.front().deviation_mm == doctest::Approx(1).epsilon(0.01));
    CHECK(rep.first_problem("wall").rfind("wall:" + std::to_string(line) + ": cutting block off the CL-data by 1.0", 0) == 0);
    // The block after it climbs back: off too; nothing else is.
    CHECK(rep.cl_deviations.size() <= 2);
  }
}

TEST_CASE("a lead-out whose end is moved off the surface normal is off the CL-data") {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cylinder), origin));
  const VerifyCase c = verify_cases()[3];  // xyzbc-head-table, iso, TCP
  const Posting p = post_wall(c, part, cylinder, origin);
  const std::vector<NcPoint> pts = parse_nc(p.text, c.dialect, p.posted.program.rotary_names, "wall");
  int last_feed = 0;
  for (const NcPoint& q : pts)
    if (!q.rapid) last_feed = q.line;
  const std::string edited = with_line(p.text, last_feed, lower_z(line_of(p.text, last_feed)));
  const VerifyReport rep = verify_text(edited, c.dialect, "wall", c.machine, part, p.tools, {}, nullptr, wall_cl(cylinder, origin));
  REQUIRE(rep.cl_deviations.size() == 1);
  CHECK(rep.cl_deviations.front().line == last_feed);
}

namespace {
// xyzac-trt changing tools at X 34 (the wall's plane, work x = 34) and the given Z and A.
Machine swinging(std::optional<double> tc_z, std::optional<double> tc_a) {
  Machine m = shipped_machine("xyzac-trt");
  m.tool_change.joints[0] = 34;
  m.tool_change.joints[2] = tc_z;
  m.tool_change.joints[3] = tc_a;
  return m;
}

Posting post_two_tools(const Machine& m, const SurfaceIndex& part, const Eigen::Vector3d& origin) {
  PostOptions o;
  o.dialect = Dialect::Iso;
  o.path.tool_length_mm = 80;
  o.part = &part;
  PostInput first{pass(cylinder, origin), "wall-1", 80, assembly_from_meridian(meridian(cylinder), holder())};
  PostInput second = first;
  second.patch = "wall-2", second.cl.tool = 2;
  Posting p;
  p.posted = post({first, second}, m, o, "WALLS", {"verify test"});
  p.text = nc_text(p.posted.program, {Dialect::Iso, false, o.path.tolerance_mm});
  p.tools = {{1, first.assembly, 80}, {2, second.assembly, 80}};
  return p;
}
}  // namespace

TEST_CASE("a tool change whose swing would cross the part is re-planned: the rotaries turn at a safe Z first" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cylinder), origin));
  // The change position: X 34 Z 20 (5 mm above the wall's top at A 0) and A -90: turning A there
  // swings the wall (85 mm from the A axis) through the tool.
  const Machine m = swinging(20.0, -90.0);
  const Posting p = post_two_tools(m, part, origin);
  INFO(p.posted.refused);
  REQUIRE(p.posted.refused.empty());
  // Safe Z now clears the part over A 0 .. -90 (its far corner rises to z = -60 + 90).
  CHECK(p.posted.program.safe_z > 40);
  const VerifyReport rep = verify_text(p.text, Dialect::Iso, "walls", m, part, p.tools, {});
  CHECK(rep.clean());
  CHECK(rep.tool_changes == 1);
  // The planner's swing before "T2 M6": without it the macro turns A at Z 100 through the part.
  std::istringstream in(p.text);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  const auto tc = std::find_if(lines.begin(), lines.end(), [](const std::string& l) { return l.find("T2 M6") != std::string::npos; });
  REQUIRE(tc != lines.end());
  auto swing = std::find_if(std::make_reverse_iterator(tc), lines.rend(), [](const std::string& l) { return l.find("A-90.") != std::string::npos; });
  REQUIRE(swing != lines.rend());
  const int swing_line = int(lines.rend() - swing);  // 1-based
  const std::string without = with_line(p.text, swing_line, "(swing removed)");
  const VerifyReport bad = verify_text(without, Dialect::Iso, "walls", m, part, p.tools, {});
  REQUIRE_FALSE(bad.clean());
  bool in_change = false;
  for (const VerifyHit& h : bad.hits) in_change |= h.tool_change && h.depth_mm > 1;
  CHECK(in_change);
  MESSAGE("without the planner's swing: " << bad.first_problem("walls"));
  CHECK(bad.first_problem("walls").find("tool change") != std::string::npos);
}

TEST_CASE("a tool change that plunges into the part is refused, naming the block after it") {
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(wall(cylinder), origin));
  // The macro moves Z to 5 (inside the wall's height) and X into the wall's plane.
  const Posting p = post_two_tools(swinging(5.0, std::nullopt), part, origin);
  REQUIRE_FALSE(p.posted.refused.empty());
  CHECK(p.posted.refused.find("tool change") != std::string::npos);
  // One tool: no tool change, nothing refused.
  PostOptions o;
  o.dialect = Dialect::Iso;
  o.part = &part;
  const Posted one = post({{pass(cylinder, origin), "wall", 80, assembly_from_meridian(meridian(cylinder), holder())}},
                          swinging(5.0, std::nullopt), o, "W", {});
  CHECK(one.refused.empty());
}

TEST_CASE("machine files: tool_change takes joint values by axis name within the limits") {
  CHECK_FALSE(shipped_machine("xyzac-trt").tool_change.joints[2].has_value());  // default: Z to the top of its travel
  test::ScratchDir dir("toolchange");
  const std::string base = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const std::string file = dir.file("m.yaml");
  test::write_text(file, base + "tool_change: {Z: 400, X: -100, A: -90}\n");
  const Machine m = load_machine(file);
  REQUIRE(m.tool_change.joints[2].has_value());
  CHECK(*m.tool_change.joints[2] == 400);
  CHECK(*m.tool_change.joints[0] == -100);
  CHECK_FALSE(m.tool_change.joints[1].has_value());
  CHECK(*m.tool_change.joints[3] == -90);  // A is rotary[0]
  CHECK_FALSE(m.tool_change.joints[4].has_value());
  test::write_text(file, base + "tool_change: {Z: 500}\n");  // Z travel ends at 450
  CHECK_THROWS_WITH_AS((void)load_machine(file), doctest::Contains("tool_change.Z"), MachineError);
  test::write_text(file, base + "tool_change: {B: 0}\n");  // no B axis
  CHECK_THROWS_WITH_AS((void)load_machine(file), doctest::Contains("B"), MachineError);
}

TEST_CASE("a part whose coarse twin of the flank stands 0.03 mm proud: judged apart, the cut is held to the design surface and the rest of the part" * doctest::test_suite("heavy")) {
  const Eigen::Vector3d origin(30, 10, -5);
  const TriMesh design_mesh = moved(wall(cone), origin);
  const TriMesh twin = moved(wall([](double z) { return cone(z) - 0.03; }), origin);
  // A floor (the hub) 1 mm below the tip, reaching under the cutter, or 0.05 mm above the tip.
  const auto floor = [&](double z) {
    return test::grid_mesh(9, 9, [&](int i, int j) { return Eigen::Vector3d(origin + Eigen::Vector3d(-10 + 5.0 * i, -40 + 10.0 * j, z)); });
  };
  const SurfaceIndex design(design_mesh);
  const VerifyCase c = verify_cases()[1];
  const Posting p = post_wall(c, design, cone, origin);
  REQUIRE(p.posted.refused.empty());
  for (const double hub : {-1.0, 0.05}) {
    CAPTURE(hub);
    const SurfaceIndex whole(merged(twin, floor(hub))), rest(floor(hub));
    VerifyOptions o;
    o.gouge_tolerance_mm = 0.01;
    // Against the whole part the twin shows the cut as a gouge of 0.03 mm (and the floor, when raised).
    const VerifyReport plain = verify_text(p.text, c.dialect, "wall", c.machine, whole, p.tools, o, &design);
    REQUIRE_FALSE(plain.clean());
    double deepest = 0;
    for (const VerifyHit& h : plain.hits) deepest = std::max(deepest, h.depth_mm);
    CHECK(deepest == doctest::Approx(hub > 0 ? 0.05 : 0.03).epsilon(0.1));
    // Judged apart: the flank against the design surface (within 0.01), the rest against the floor.
    o.apart.cut_part = &rest;
    o.apart.design_gouge_tolerance_mm = 0.01;
    const VerifyReport apart = verify_text(p.text, c.dialect, "wall", c.machine, whole, p.tools, o, &design);
    if (hub < 0) {
      CHECK(apart.clean());
    } else {
      // (The raised floor also stands in the way of the approach: rapids posted without it hit it.)
      int gouges = 0;
      for (const VerifyHit& h : apart.hits) {
        if (h.rapid) continue;
        ++gouges;
        CHECK(h.kind() == "gouge");
        CHECK(h.depth_mm == doctest::Approx(0.05).epsilon(0.1));
        CHECK(h.point.z() == doctest::Approx(origin.z() + hub));  // on the floor, not on the flank
      }
      CHECK(gouges > 10);
    }
    // The design surface itself cut 0.03 mm too deep is a gouge when judged apart.
    const VerifyReport deep = verify_text(p.text, c.dialect, "wall", c.machine, whole, p.tools, o, nullptr);
    CHECK(deep.clean() == plain.clean());  // without the design surface nothing is judged apart
  }
  // A program 0.03 mm into the design surface: posted against the twin-free design 0.03 mm deeper.
  const SurfaceIndex sunk(moved(wall([](double z) { return cone(z) - 0.03; }), origin));
  VerifyOptions o;
  o.gouge_tolerance_mm = 0.01;
  const SurfaceIndex rest(floor(-1));
  o.apart.cut_part = &rest;
  o.apart.design_gouge_tolerance_mm = 0.01;
  const VerifyReport into = verify_text(p.text, c.dialect, "wall", c.machine, sunk, p.tools, o, &sunk);
  REQUIRE_FALSE(into.clean());
  for (const VerifyHit& h : into.hits) CHECK(h.depth_mm == doctest::Approx(0.03).epsilon(0.1));
}

TEST_CASE("a floor rising away from the flank: the links are lifted off it instead of running the cutter into it" *
          doctest::test_suite("heavy")) {
  // Beyond the cutter's reach (x < -3.2, the wall at x = r(z) > 0) a ramp rises at 1:2 away from the
  // flank. The plain lead point (3.5 mm out along the normal, tip level with the cut) and its rapid
  // put the cutter's end ~2 mm into the ramp, and twice as far out deeper still; lifted along the axis
  // by a lead the link clears it by the clearance.
  const Eigen::Vector3d origin(30, 10, -5);
  TriMesh part_mesh = wall(cone);
  const int base = int(part_mesh.vertices.size());
  for (const Eigen::Vector3d& v : {Eigen::Vector3d(-3.2, -40, -0.2), Eigen::Vector3d(-3.2, 40, -0.2),
                                   Eigen::Vector3d(-30, 40, -0.2 + 0.5 * 26.8), Eigen::Vector3d(-30, -40, -0.2 + 0.5 * 26.8)})
    part_mesh.vertices.push_back(v);
  part_mesh.faces.push_back({base, base + 2, base + 1});
  part_mesh.faces.push_back({base, base + 3, base + 2});
  const SurfaceIndex part(moved(part_mesh, origin));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const Posting p = post_wall(c, part, cone, origin);
  CHECK(p.posted.links_checked);
  CHECK(p.posted.refused.empty());
  CHECK(p.posted.min_link_clearance_mm >= PostOptions{}.clearance_mm);
  const VerifyReport rep = verify_text(p.text, c.dialect, "wall", c.machine, part, p.tools, {});
  CHECK(rep.clean());
}

namespace {
// The cylinder's wall (tool frame: the wall x = 4, the tip at z = 0, the pass y -20 .. 20) with a
// plate 9 mm behind the tool at the lead-out, 20 mm high: a lead of 3 mm at a clearance of 1.5 mm
// fits (the plain lead's far side 2 mm from it); at 6 and 3 mm or 12 and 6 mm (a retry's) none of
// the planner's directions does. `fin`: a floor 2 mm under the tip and, at the lead-in, a fin whose
// top edge stands 0.01 mm under the tip plane 4.5 mm beside the plain lead point's axis (0.5 mm off
// the cutter's rim).
TriMesh slot_part(const Eigen::Vector3d& origin, bool fin) {
  TriMesh mesh = merged(wall(cylinder), test::box_mesh({-10, 0, -2.5}, {-9, 40, 20}));
  if (fin) {
    mesh = merged(mesh, test::box_mesh({-30, -40, -3}, {8, 40, -2}));
    mesh = merged(mesh, test::box_mesh({-16, -25.5, -2.5}, {2, -24.5, -0.01}));
  }
  return moved(mesh, origin);
}

PostOptions slot_options(const VerifyCase& c, const SurfaceIndex& part) {
  PostOptions o;
  o.dialect = c.dialect;
  o.path.tool_length_mm = 80;
  o.part = &part;
  o.gouge_tolerance_mm = 0.01;
  o.clearance_mm = 1.5;
  o.lead_mm = 3;
  return o;
}
}  // namespace

TEST_CASE("leads are planned as the back-simulation judges them: an edge beside the tool's end over a floor, a narrow slot at the lead-out") {
  // The collision check that judged leads before saw the floor, not the fin, from every slab that
  // could reach the fin; the back-simulation sees it (from 4.25 mm up the cutter) and the rapid
  // ending beside it 0.5 mm close. The retries doubled lead and clearance for both leads, and the
  // lead-out, with no clear point at those, took the plain one unchecked: 4 mm into the plate (HECC
  // impeller all-patches: 1.9 mm into the next blade), and the program was refused. Judged as the
  // back-simulation judges, the lead-in turns away from the fin and the lead-out fits the slot at
  // the first try.
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(slot_part(origin, true));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const PostOptions o = slot_options(c, part);
  const PostInput in{pass(cylinder, origin), "wall", 80, assembly_from_meridian(meridian(cylinder), holder())};
  const Posted p = post({in}, c.machine, o, "WALL", {"verify test"});
  CHECK_MESSAGE(p.refused.empty(), p.refused);
  CHECK(p.links_checked);
  CHECK(p.min_link_clearance_mm >= o.clearance_mm);
  // The leads as posted: 3 mm off the first and the last pose, the lead-in turned away from the fin.
  const ClProgram& cl = p.sections.at(0).cl;
  const ToolPose &lead_in = cl.moves.front().pose, &first = cl.moves.at(1).pose;
  const ToolPose &last = cl.moves.at(cl.moves.size() - 2).pose, &lead_out = cl.moves.back().pose;
  CHECK((lead_in.tip - first.tip).norm() == doctest::Approx(3));
  CHECK((lead_out.tip - last.tip).norm() == doctest::Approx(3));
  CHECK(lead_in.tip.y() - origin.y() > -20);  // not toward the fin (y < -24.5)
  // The program's own back-simulation: no gouge, every rapid the clearance off the part.
  const std::string text = nc_text(p.program, {c.dialect, false, o.path.tolerance_mm});
  const VerifyReport rep = verify_text(text, c.dialect, "wall", c.machine, part, {{1, in.assembly, 80}}, {});
  CHECK(rep.hits.empty());
  double rapid_min = INFINITY;
  for (const VerifiedBlock& b : rep.blocks)
    if (b.rapid) rapid_min = std::min({rapid_min, b.min_clearance_mm[0], b.min_clearance_mm[1], b.min_clearance_mm[2]});
  CHECK(rapid_min >= o.clearance_mm);
  // The safe Z of the first try: the part's top (z 15) plus the safe height, not a retry's doubled one.
  CHECK(p.program.safe_z < 15 + 2 * o.safe_height_mm);
}

TEST_CASE("a retry keeps the configured lead where its doubled one has no clear point: refused for the rapid it cannot move, not for a lead" * doctest::test_suite("heavy")) {
  // A rapid along the wall in the middle of the pass (y -2 to 0) touches it: no retry moves it, and
  // each retry doubles the lead and the clearance, at which the lead-out has no clear point. The
  // refusal names that rapid, and the lead-out of the program it refuses keeps the configured 3 mm
  // and 1.5 mm (before, the doubled plain point went into the plate unchecked).
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(slot_part(origin, false));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const PostOptions o = slot_options(c, part);
  PostInput in{pass(cylinder, origin), "wall", 80, assembly_from_meridian(meridian(cylinder), holder())};
  REQUIRE(in.cl.moves.size() == 25);
  ClMove& touching = in.cl.moves[12];  // pose 10 of 0..20, after the two approach rapids
  REQUIRE(touching.pose.tip.y() == doctest::Approx(origin.y()));
  touching.rapid = true;
  const Posted p = post({in}, c.machine, o, "WALL", {"verify test"});
  INFO(p.refused);
  REQUIRE(p.refused.find("WALL.nc:") != std::string::npos);
  CHECK(p.refused.find("(rapid)") != std::string::npos);
  // The refused program: the touching rapid is all that comes within the clearance of the part.
  const std::string text = nc_text(p.program, {c.dialect, false, o.path.tolerance_mm});
  VerifyOptions vo;
  vo.link_clearance_mm = o.clearance_mm;
  const VerifyReport rep = verify_text(text, c.dialect, "wall", c.machine, part, {{1, in.assembly, 80}}, vo);
  REQUIRE_FALSE(rep.hits.empty());
  for (const VerifyHit& h : rep.hits) {
    CAPTURE(h.line);
    CHECK(h.rapid);
    const double y = rep.motion.at(size_t(h.position)).pose.tip.y() - origin.y();
    CHECK(y >= -2 - 1e-6);  // on the rapid from pose 9 (y -2) to pose 10 (y 0)
    CHECK(y <= 1e-6);
  }
  // The lead-in, in the open, twice doubled (12 mm); the lead-out, in the slot, the configured 3 mm.
  const ClProgram& cl = p.sections.at(0).cl;
  CHECK((cl.moves.front().pose.tip - cl.moves.at(1).pose.tip).norm() == doctest::Approx(12));
  CHECK((cl.moves.back().pose.tip - cl.moves.at(cl.moves.size() - 2).pose.tip).norm() == doctest::Approx(3));
}

TEST_CASE("a lead with no clear point is refused in one line naming the patch, the lead and its pose, before any back-simulation" * doctest::test_suite("heavy")) {
  // The plate 6 mm behind the tool: the cutter's far side 2 mm from it during the cut, and every lead
  // direction of the planner, 3 or 6 mm out, brings the assembly within 1.5 mm of the plate or the wall.
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(merged(wall(cylinder), test::box_mesh({-7, 0, -2.5}, {-6, 40, 20})), origin));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const PostOptions o = slot_options(c, part);
  const PostInput in{pass(cylinder, origin), "wall", 80, assembly_from_meridian(meridian(cylinder), holder())};
  const Posted p = post({in}, c.machine, o, "WALL", {"verify test"});
  INFO(p.refused);
  CHECK(p.refused.rfind("link planning: patch 'wall': no lead-out off CL move 22 (tip 30.000, 30.000, -5.000)", 0) == 0);
  CHECK(p.refused.find("at lead 3 and 6 mm, clearance 1.5 mm") != std::string::npos);
  // Why: all 54 candidates (27 directions, 3 and 6 mm out) counted, and the nearest miss named.
  CHECK(p.refused.find("(36 candidates fail in the feed along the lead, 18 in the rapid up the tool axis; the nearest "
                       "miss: the tool 0.500 mm from the part in the rapid)") != std::string::npos);
  CHECK(p.refused.find('\n') == std::string::npos);
  CHECK_FALSE(p.links_checked);
}

TEST_CASE("a cut whose end has no clear lead is shortened to the outermost move that can be left, and that program posts clean" *
          doctest::test_suite("heavy")) {
  // The plate of the refusal above stands behind the second half of the pass (y >= 0 of -20..20):
  // there no lead-out is clear, before it the plate is out of reach. clear_lead_range keeps the
  // lead-in (y = -20, in the open) and moves the lead-out inwards to the last pose that can be left.
  const Eigen::Vector3d origin(30, 10, -5);
  const SurfaceIndex part(moved(merged(wall(cylinder), test::box_mesh({-7, 0, -2.5}, {-6, 40, 20})), origin));
  const VerifyCase c = verify_cases()[1];  // xyzbc-trt, iso: joints
  const PostOptions o = slot_options(c, part);
  const PostInput in{pass(cylinder, origin), "wall", 80, assembly_from_meridian(meridian(cylinder), holder())};
  const LeadRange r = clear_lead_range(in.cl, in.assembly, o);
  INFO(r.why);
  CHECK(r.first == 2);  // after the CL-data's two approach rapids
  CHECK(r.last == 22);  // pose 20 of 0..20, before its axial lead-out
  CHECK(r.trimmed());
  CHECK_FALSE(r.none);
  CHECK(r.kept_first == r.first);
  CHECK(r.why.rfind("no lead-out off CL move 22 (tip 30.000, 30.000, -5.000) is clear of the part", 0) == 0);
  const double y_kept = in.cl.moves.at(r.kept_last).pose.tip.y() - origin.y();
  CAPTURE(y_kept);
  CHECK(y_kept <= 0);   // not beside the plate (from y 0 on): left along the wall away from it
  CHECK(y_kept > -10);  // no farther from it than the cutter's radius, the lead and the clearance
  // Shortened there, the program posts clean; one pose longer, its lead-out has no clear point.
  const auto cut_at = [&](size_t last) {
    PostInput shorter = in;
    shorter.cl.moves.erase(shorter.cl.moves.begin() + long(last) + 1, shorter.cl.moves.end());
    return post({shorter}, c.machine, o, "WALL", {"verify test"});
  };
  const Posted kept = cut_at(r.kept_last);
  CHECK_MESSAGE(kept.refused.empty(), kept.refused);
  CHECK(kept.links_checked);
  CHECK(kept.min_link_clearance_mm >= o.clearance_mm);
  const Posted longer = cut_at(r.kept_last + 1);
  CHECK(longer.refused.find(fmt::format("no lead-out off CL move {} ", r.kept_last + 1)) != std::string::npos);
}

TEST_CASE("a cut that the machine's straight joint moves take into the part is linearised finer, said in the program, and posts clean") {
  // A ball-end tool (Ø6) rolling along a floor z = 100 while its axis leans from -30° to +30° in x-z:
  // the ball's lowest point stays on the floor, so the intended motion cuts nothing. On xyzbc-trt
  // (no TCP) the table's B turns between the points; at a coarse linearisation (0.05 mm, 0.5°) the
  // straight joint moves between them dip into the floor (measured: 0.034 mm; 0.169 mm at 0.2 mm),
  // more than the 0.01 mm gouge tolerance.
  const Machine m = shipped_machine("xyzbc-trt");
  std::vector<Eigen::Vector2d> ball;
  for (int k = 0; k <= 12; ++k) {
    const double z = 3.0 * k / 12;
    ball.emplace_back(z, std::sqrt(std::max(0.0, 9 - (3 - z) * (3 - z))));
  }
  ball.emplace_back(25, 3);
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 12; ++i) {
    const double lean = (-30 + 5.0 * i) * M_PI / 180;
    const Eigen::Vector3d axis(std::sin(lean), 0, std::cos(lean));
    const Eigen::Vector3d centre(-30 + 5.0 * i, 0, 103);  // the ball's centre, 3 mm above the floor
    poses.push_back({centre - 3 * axis, axis});
  }
  const SurfaceIndex floor(test::box_mesh({-60, -20, 90}, {60, 20, 100}, 6));
  PostOptions o;
  o.dialect = Dialect::Iso;
  o.path.tool_length_mm = 80;
  o.path.tolerance_mm = 0.05;
  o.path.angle_tolerance_deg = 0.5;
  o.part = &floor;
  o.gouge_tolerance_mm = 0.01;
  const PostInput in{flank_program("FLOOR", poses, ball, 600, 10000, 5, 30), "floor", 80,
                     assembly_from_meridian(ball, holder())};
  const Posted p = post({in}, m, o, "FLOOR", {"verify test"});
  INFO(p.refused);
  CHECK(p.refused.empty());
  MESSAGE("refined ", p.refined, " times: ", p.tolerance_mm, " mm, ", p.angle_tolerance_deg, " deg; ", p.refined_for);
  REQUIRE(p.refined >= 1);
  CHECK(p.refined <= Posted::kMaxRefinements);
  CHECK(p.tolerance_mm == doctest::Approx(0.05 / std::pow(2, p.refined)));
  CHECK(p.angle_tolerance_deg == doctest::Approx(0.5 / std::pow(2, p.refined)));
  CHECK(p.refined_for.find("tool gouge") != std::string::npos);
  // The text as written (blending at the refined tolerance), read back and judged on its own: clean;
  // the header says why the chords are finer than asked.
  const std::string text = nc_text(p.program, {o.dialect, false, p.tolerance_mm});
  CHECK(text.find("linearisation refined to") != std::string::npos);
  VerifyOptions vo;
  vo.gouge_tolerance_mm = 0.01;
  vo.link_clearance_mm = o.clearance_mm;
  const VerifyReport rep = verify_text(text, o.dialect, "FLOOR.nc", m, floor, {{1, in.assembly, 80}}, vo);
  CHECK(rep.clean());
  // At the coarse linearisation alone the same text is not clean: that is what was refined away.
  PostOptions coarse = o;
  coarse.part = nullptr;
  const Posted unchecked = post({in}, m, coarse, "FLOOR", {"verify test"});
  const VerifyReport before = verify_text(nc_text(unchecked.program, {o.dialect, false, 0.05}), o.dialect, "FLOOR.nc", m, floor,
                                          {{1, in.assembly, 80}}, vo);
  CHECK(!before.hits.empty());
  // A floor 0.05 mm higher is cut by the intended motion itself: no linearisation helps, the program
  // is refused after the refinements and says how fine it went.
  const SurfaceIndex higher(test::box_mesh({-60, -20, 90}, {60, 20, 100.05}, 6));
  PostOptions h = o;
  h.part = &higher;
  const Posted r = post({in}, m, h, "FLOOR", {"verify test"});
  CHECK(r.refined == Posted::kMaxRefinements);
  CHECK(r.refused.find("tool gouge") != std::string::npos);
  CHECK(r.refused.find("(linearised down to 0.00625 mm, 0.0625 deg)") != std::string::npos);
}
