#include "postproc/gcode.h"

#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <regex>
#include <set>
#include <sstream>
#include <sys/wait.h>

#include "core/errors.h"
#include "kinematics/machine.h"
#include "tests/postproc/small_patch.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

Machine shipped(const std::string& name) { return load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml"); }

// Every dialect on a machine it suits, joints and TCP both represented.
struct Case {
  std::string label;
  Machine machine;
  Dialect dialect;
};
std::vector<Case> cases() {
  Machine trt = shipped("xyzac-trt");  // joints under identity kinematics
  Machine trt_kins = trt;              // LinuxCNC with its trt kinematics active: tip + angles
  trt_kins.controller.linuxcnc_trt = true;
  trt_kins.name = "xyzac-trt-kins";
  return {{"xyzac-trt", trt, Dialect::LinuxCnc},
          {"xyzac-trt-kins", trt_kins, Dialect::LinuxCnc},
          {"xyzbc-trt", shipped("xyzbc-trt"), Dialect::Iso},
          {"xyzbc-head-table", shipped("xyzbc-head-table"), Dialect::Iso},
          {"xyzca-head-head", shipped("xyzca-head-head"), Dialect::Heidenhain},
          {"xyzbc-trt-heidenhain", shipped("xyzbc-trt"), Dialect::Heidenhain},
          {"xyzbc-nutating", shipped("xyzbc-nutating"), Dialect::Sinumerik}};
}

PostOptions options(Dialect d) {
  PostOptions o;
  o.dialect = d;
  o.path.tool_length_mm = 60;
  return o;
}

Posted post_small(const Case& c, bool line_numbers = false) {
  PostOptions o = options(c.dialect);
  o.line_numbers = line_numbers;
  return post({{test::small_patch(), "small", 0}}, c.machine, o, "SMALL-PATCH",
              {"flankcam test", "fitted tolerance 0.0040 mm"});
}

std::vector<NcMove> moves_of(const NcProgram& p) {
  std::vector<NcMove> out;
  for (const NcBlock& b : p.blocks)
    if (const auto* m = std::get_if<NcMove>(&b)) out.push_back(*m);
  return out;
}

double angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

// How the controller moves between two programmed positions: joints linearly, or under TCP the tip on
// a line with the rotary angles linear.
ToolPose controller_pose(const Machine& m, const Joints& a, const Joints& b, double f, double tool_length) {
  Joints q;
  q.linear = (1 - f) * a.linear + f * b.linear;
  for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * a.rotary[k] + f * b.rotary[k];
  return programmed_pose(m, q, tool_length);
}

}  // namespace

TEST_CASE("every dialect read back through the forward kinematics reproduces the CL poses within tolerance") {
  const ClProgram cl = test::small_patch();
  for (const Case& c : cases()) {
    CAPTURE(c.label);
    const PostOptions o = options(c.dialect);
    const Posted posted = post_small(c);
    const std::string text = nc_text(posted.program, {c.dialect, false, o.path.tolerance_mm});
    const std::vector<NcPoint> points = parse_nc(text, c.dialect, posted.program.rotary_names, c.label);
    const std::vector<NcMove> moves = moves_of(posted.program);
    REQUIRE(points.size() == moves.size());
    const bool tcp = c.machine.controller.tcp || c.machine.controller.linuxcnc_trt;
    int cl_hits = 0, feeds = 0;
    double worst_tip = 0, worst_axis = 0, worst_between = 0;
    for (size_t i = 0; i < points.size(); ++i) {
      CAPTURE(i);
      const NcPoint& pt = points[i];
      CHECK(pt.rapid == moves[i].rapid);
      if (pt.known != AxesAll) continue;  // the first safe-Z block: X, Y and the angles not stated yet
      if (c.dialect != Dialect::LinuxCnc) CHECK(pt.tcp == tcp);
      const ToolPose sim = programmed_pose(c.machine, pt.at, o.path.tool_length_mm);
      worst_tip = std::max(worst_tip, (sim.tip - moves[i].pose.tip).norm());
      worst_axis = std::max(worst_axis, angle(sim.axis, moves[i].pose.axis));
      if (moves[i].cl_move >= 0) {  // ends exactly at a CL pose
        ++cl_hits;
        CHECK((sim.tip - cl.moves[size_t(moves[i].cl_move)].pose.tip).norm() < 2e-4);
        CHECK(angle(sim.axis, cl.moves[size_t(moves[i].cl_move)].pose.axis) < 1e-5);
      }
      if (pt.rapid || i == 0) continue;
      ++feeds;
      CHECK(pt.f > 0);
      // Inside the block: the controller's motion against the intended one (tip on the line, axis slerped).
      for (double f : {0.125, 0.25, 0.5, 0.75, 0.875}) {
        const ToolPose got = controller_pose(c.machine, points[i - 1].at, pt.at, f, o.path.tool_length_mm);
        const ToolPose want = interpolate(moves[i - 1].pose, moves[i].pose, f);
        worst_between = std::max(worst_between, (got.tip - want.tip).norm());
        CHECK(angle(got.axis, want.axis) * 180 / M_PI < o.path.angle_tolerance_deg + 1e-4);
      }
    }
    MESSAGE(c.label << ": " << feeds << " feed blocks, end points within " << worst_tip << " mm / " << worst_axis
                    << " rad, inside blocks " << worst_between << " mm");
    CHECK(cl_hits == int(cl.moves.size()));
    CHECK(worst_tip < 2e-4);  // 4 decimals of mm and degrees at ~100 mm from the rotary axes
    CHECK(worst_axis < 1e-5);
    CHECK(worst_between < o.path.tolerance_mm + 2e-4);
  }
}

TEST_CASE("the safe approach turns the rotaries only at safe Z, above every programmed point") {
  for (const Case& c : cases()) {
    CAPTURE(c.label);
    const Posted posted = post_small(c);
    const NcProgram& p = posted.program;
    const std::vector<NcMove> moves = moves_of(p);
    double top = -1e9;
    for (const NcMove& m : moves)
      if (m.at.linear.z() < p.safe_z - 1e-9) top = std::max(top, m.at.linear.z());
    CHECK(p.safe_z >= top);
    CHECK((moves.front().axes == AxisZ && moves.front().at.linear.z() == p.safe_z));
    CHECK((moves.back().axes == AxisZ && moves.back().at.linear.z() == p.safe_z));
    for (size_t i = 1; i < moves.size(); ++i)
      if (moves[i].at.rotary != moves[i - 1].at.rotary && moves[i].rapid) {
        CHECK(moves[i].axes == AxesRotary);
        CHECK(moves[i].at.linear.z() == p.safe_z);
      }
  }
}

TEST_CASE("inverse-time F is never faster than the programmed feed and equals it where no axis limits") {
  const Case c = cases()[2];  // xyzbc-trt, iso
  const Posted posted = post_small(c);
  const std::vector<NcMove> moves = moves_of(posted.program);
  int exact = 0;
  for (size_t i = 1; i < moves.size(); ++i) {
    if (moves[i].rapid) continue;
    const double dist = (moves[i].pose.tip - moves[i - 1].pose.tip).norm();
    const double minutes = 1 / moves[i].inverse_time;
    CHECK(dist / minutes <= 800 * (1 + 1e-9));
    exact += std::abs(dist / minutes - 800) < 1e-6;
  }
  CHECK(exact > 0);
}

TEST_CASE("golden NC programs for the small fixed patch, one per dialect and machine") {
  for (const Case& c : cases()) {
    CAPTURE(c.label);
    const Posted posted = post_small(c, c.dialect == Dialect::Iso);
    const std::string text = nc_text(posted.program, {c.dialect, c.dialect == Dialect::Iso, 0.005});
    const std::string golden = std::string(TEST_DATA) + "/golden/small-patch-" + c.label + file_extension(c.dialect);
    if (std::getenv("FLANKCAM_UPDATE_GOLDEN")) test::write_text(golden, text);
    CHECK(text == test::read_text(golden));
    CHECK(text.find("-0.0000") == std::string::npos);
    CHECK(text.find("nan") == std::string::npos);
  }
}

TEST_CASE("line numbers do not change what is read back") {
  const Case c = cases()[4];
  const Posted posted = post_small(c);
  const auto plain = parse_nc(nc_text(posted.program, {Dialect::Iso, false, 0.005}), Dialect::Iso, posted.program.rotary_names, "a");
  const std::string numbered_text = nc_text(posted.program, {Dialect::Iso, true, 0.005});
  CHECK(std::regex_search(numbered_text, std::regex("\nN[0-9]+ G21 G90")));
  const auto numbered = parse_nc(numbered_text, Dialect::Iso, posted.program.rotary_names, "b");
  REQUIRE(plain.size() == numbered.size());
  for (size_t i = 0; i < plain.size(); ++i) CHECK(plain[i].at.linear == numbered[i].at.linear);
}

TEST_CASE("all patches in one program: a tool change per tool, each cut approached and left at safe Z") {
  const Case c = cases()[3];  // head-table, iso TCP
  ClProgram a = test::small_patch(), b = test::small_patch();
  b.tool = 2;
  for (ClMove& m : b.moves) m.pose.tip.z() += 3;  // a second, offset cut
  const Posted posted = post({{a, "first", 0}, {b, "second", 0}}, c.machine, options(c.dialect), "ALL", {});
  REQUIRE(posted.sections.size() == 2);
  const std::string text = nc_text(posted.program, {Dialect::Iso, false, 0.005});
  CHECK(text.find("T1 M6") != std::string::npos);
  CHECK(text.find("T2 M6") != std::string::npos);
  CHECK(text.find("(patch second)") != std::string::npos);
  const auto points = parse_nc(text, Dialect::Iso, posted.program.rotary_names, "all.nc");
  int tool_changes = 0, last_tool = 0;
  for (const NcPoint& p : points)
    if (p.tool != last_tool) ++tool_changes, last_tool = p.tool;
  CHECK(tool_changes == 2);
  CHECK(last_tool == 2);
}

TEST_CASE("bad programs and impossible posts are refused with the line or the field") {
  const auto error = [](const std::string& text, Dialect d) {
    try {
      (void)parse_nc(text, d, {"A", "C"}, "bad.nc");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  CHECK(error("G0 X1 Y2\nG1 Q5 F1\nM30\n", Dialect::Iso) == "bad.nc:2: 'Q5': no such axis on this machine");
  CHECK(error("G0 X1\n", Dialect::Iso) == "bad.nc:1: the program has no end (M2, M30 or END PGM)");
  CHECK(error("X1 Y2\nM2\n", Dialect::LinuxCnc) == "bad.nc:1: a move before any G0/G1");
  CHECK(error("G0 X1.2.3\nM2\n", Dialect::LinuxCnc) == "bad.nc:1: '1.2.3' is not a number");
  CHECK(error("G0 X1 (open\nM2\n", Dialect::LinuxCnc) == "bad.nc:1: unbalanced parentheses");
  CHECK(error("0 BEGIN PGM A MM\n1 L X1 FMAX\n2 END PGM A MM\n", Dialect::Heidenhain) ==
        "bad.nc:2: 'X1': Heidenhain coordinates carry a sign");
  CHECK(error("G0 X1\nG2 X3\nM30\n", Dialect::Iso) == "bad.nc:2: G2 is not a code flankcam writes");

  Machine tcp = shipped("xyzbc-head-table");  // TCP by G43.4, which LinuxCNC lacks
  CHECK_THROWS_WITH_AS((void)post({{test::small_patch(), "small", 0}}, tcp, options(Dialect::LinuxCnc), "X", {}),
                       doctest::Contains("post.dialects: linuxcnc: LinuxCNC has no G43.4"), InputError);
  // A pose beyond the A table's tilt: the patch and pose are named.
  ClProgram steep = test::small_patch();
  steep.moves[3].pose.axis = Eigen::Vector3d(0, -0.8, -0.6);
  CHECK_THROWS_WITH_AS((void)post({{steep, "steep", 0}}, cases()[0].machine, options(Dialect::LinuxCnc), "X", {}),
                       doctest::Contains("patch 'steep': pose 3"), MachineError);
  ClProgram empty = test::small_patch();
  empty.moves.clear();
  CHECK_THROWS_WITH_AS((void)post({{empty, "empty", 0}}, cases()[0].machine, options(Dialect::LinuxCnc), "X", {}),
                       "patch 'empty': the CL-data has no GOTO", InputError);
}

// LinuxCNC's own interpreter as the independent judge of the linuxcnc programs.
namespace {
struct Rs274Move {
  int source_line;
  std::array<double, 6> xyzabc;
  bool feed;
};
std::string rs274_path() {
  for (const char* p : {"/usr/bin/rs274", "/usr/local/bin/rs274"})
    if (std::filesystem::exists(p)) return p;
  return {};
}
}  // namespace

TEST_CASE("LinuxCNC's rs274 accepts the linuxcnc programs and reaches the same end points") {
  const std::string rs274 = rs274_path();
  if (rs274.empty()) {
    // CI installs linuxcnc-uspace and sets FLANKCAM_REQUIRE_RS274=1, so this cannot pass silently there.
    const char* required = std::getenv("FLANKCAM_REQUIRE_RS274");
    CHECK_MESSAGE(!(required && std::string(required) == "1"), "rs274 is required but not installed");
    MESSAGE("SKIPPED: rs274 (Debian package linuxcnc-uspace) is not installed; the LinuxCNC check did not run");
    return;
  }
  for (const Case& c : cases()) {
    if (c.dialect != Dialect::LinuxCnc) continue;
    CAPTURE(c.label);
    test::ScratchDir dir("rs274");
    const Posted posted = post_small(c, true);
    const std::string text = nc_text(posted.program, {Dialect::LinuxCnc, true, 0.005});
    test::write_text(dir.file("p.ngc"), text);
    // The stand-alone interpreter reads the tool table in inches.
    test::write_text(dir.file("tool.tbl"), "T1 P1 Z" + std::to_string(40.0 / 25.4) + " D" + std::to_string(18.0 / 25.4) + " ;\n");
    test::write_text(dir.file("fresh.var"), "");
    const std::string cmd = "cd " + dir.path.string() + " && HOME=" + dir.path.string() + " " + rs274 +
                            " -g -t tool.tbl -v fresh.var p.ngc out.txt < /dev/null > log.txt 2> err.txt";
    const int status = std::system(cmd.c_str());
    INFO(test::read_text(dir.file("err.txt")));
    REQUIRE(WIFEXITED(status));
    REQUIRE(WEXITSTATUS(status) == 0);
    const std::string out = test::read_text(dir.file("out.txt"));
    // "   42 N0150  STRAIGHT_FEED(1.0000, 2.0000, 3.0000, 4.0000, 0.0000, 5.0000)"
    const std::regex move(R"(N(\d+)\s+(STRAIGHT_TRAVERSE|STRAIGHT_FEED)\(([^)]*)\))");
    std::vector<Rs274Move> got;
    for (auto it = std::sregex_iterator(out.begin(), out.end(), move); it != std::sregex_iterator(); ++it) {
      Rs274Move m{std::stoi((*it)[1]), {}, (*it)[2] == "STRAIGHT_FEED"};
      std::istringstream values((*it)[3]);
      std::string v;
      for (size_t k = 0; k < 6 && std::getline(values, v, ','); ++k) m.xyzabc[k] = std::stod(v);
      got.push_back(m);
    }
    const std::vector<NcPoint> ours = parse_nc(text, Dialect::LinuxCnc, posted.program.rotary_names, "p.ngc");
    REQUIRE(got.size() == ours.size());
    // The rotary words of this machine in rs274's a, b, c slots.
    const auto slot = [](const std::string& n) { return n == "A" ? 3 : n == "B" ? 4 : 5; };
    for (size_t i = 0; i < ours.size(); ++i) {
      CAPTURE(i);
      CHECK(got[i].feed == !ours[i].rapid);
      for (unsigned k = 0; k < 5; ++k) {
        if (!(ours[i].known & (1u << k))) continue;
        const double want = k < 3 ? ours[i].at.linear[k] : ours[i].at.rotary[k - 3];
        const size_t s = k < 3 ? k : size_t(slot(posted.program.rotary_names[k - 3]));
        CHECK(std::abs(got[i].xyzabc[s] - want) < 5e-5);
      }
    }
    MESSAGE(c.label << ": rs274 accepted " << got.size() << " moves, all end points equal to 4 decimals");
  }
}

// Issue 12 item 8: T1e30 was int(1e30), undefined behaviour.
TEST_CASE("NC reader: tool numbers, feeds and coordinates outside their ranges name the line") {
  const auto error = [](const std::string& text, Dialect d) {
    try {
      (void)parse_nc(text, d, {"A", "C"}, "bad.nc");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  CHECK(error("T1e30 M6\nG0 X1\nM30\n", Dialect::Iso) == "bad.nc:1: tool number '1E30' is outside 0..99999");
  CHECK(error("T-1 M6\nG0 X1\nM30\n", Dialect::Iso) == "bad.nc:1: tool number '-1' is outside 0..99999");
  CHECK(error("T2.5 M6\nG0 X1\nM30\n", Dialect::LinuxCnc) == "bad.nc:1: tool number '2.5' is not a whole number");
  CHECK(error("G0 X1e300\nM30\n", Dialect::Iso) == "bad.nc:1: X '1E300' is outside -1e+06..1e+06");
  CHECK(error("G1 X1 F1e300\nM30\n", Dialect::Iso) == "bad.nc:1: F '1E300' is outside 0..1e+07");
  CHECK(error("G1 X1 F-5\nM30\n", Dialect::Sinumerik) == "bad.nc:1: F '-5' is outside 0..1e+07");
  CHECK(error("0 BEGIN PGM A MM\n1 TOOL CALL 1e30 Z S1000\n2 END PGM A MM\n", Dialect::Heidenhain) ==
        "bad.nc:2: tool number '1e30' is outside 0..99999");
  CHECK(error("0 BEGIN PGM A MM\n1 L X+1e300 FMAX\n2 END PGM A MM\n", Dialect::Heidenhain) ==
        "bad.nc:2: X '+1e300' is outside -1e+06..1e+06");
  CHECK(error("G0 X\"a\nM30\n", Dialect::Iso).find('\n') == std::string::npos);
  const std::vector<NcPoint> ok = parse_nc("T99999 M6\nG1 X-1e6 C1e6 F1e7\nM30\n", Dialect::Iso, {"A", "C"}, "ok.nc");
  REQUIRE(ok.size() == 1);
  CHECK(ok[0].tool == 99999);
  CHECK(ok[0].at.linear.x() == -1e6);
  CHECK(ok[0].f == 1e7);
}

TEST_CASE("one dialect table: names and aliases parse back, extensions differ, machine files accept the aliases") {
  std::set<std::string> extensions;
  for (const DialectInfo& i : dialect_table()) {
    CAPTURE(i.name);
    CHECK(parse_dialect(i.name) == i.dialect);
    CHECK(to_string(i.dialect) == i.name);
    for (const std::string& a : i.aliases) CHECK(parse_dialect(a) == i.dialect);
    CHECK(file_extension(i.dialect) == i.extension);
    CHECK(extensions.insert(i.extension).second);
    CHECK(dialect_names().find(i.name) != std::string::npos);
    CHECK_FALSE(i.help.empty());
  }
  CHECK(dialect_table().size() == 4);
  CHECK(dialect_names() == "iso (or fanuc), linuxcnc, heidenhain, sinumerik");
  CHECK_THROWS_WITH_AS((void)parse_dialect("klingon"),
                       "dialect: 'klingon' is not one of iso (or fanuc), linuxcnc, heidenhain, sinumerik", InputError);

  for (const char* name : {"xyzac-trt", "xyzbc-trt", "xyzbc-head-table", "xyzbc-nutating", "xyzca-head-head"}) {
    CAPTURE(name);
    const Machine m = shipped(name);
    CHECK(to_string(machine_dialect(m)) == m.controller.dialect);
  }
  test::ScratchDir dir("dialect-table");
  std::string text = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const size_t at = text.find("dialect: linuxcnc");
  REQUIRE(at != std::string::npos);
  const auto with = [&](const std::string& d) {
    std::string t = text;
    test::write_text(dir.file("m.yaml"), t.replace(at, 17, "dialect: " + d));
    return load_machine(dir.file("m.yaml"));
  };
  CHECK(machine_dialect(with("fanuc")) == Dialect::Iso);  // was rejected while --dialect fanuc worked
  CHECK(machine_dialect(with("sinumerik")) == Dialect::Sinumerik);
  CHECK_THROWS_WITH_AS((void)machine_dialect(with("klingon")),
                       (dir.file("m.yaml") + ":14: controller.dialect: 'klingon' is not one of iso (or fanuc), linuxcnc, "
                                             "heidenhain, sinumerik").c_str(),
                       MachineError);
  CHECK_THROWS_WITH_AS((void)machine_dialect(with("\"fa\\nnuc\"")), doctest::Contains("controller.dialect: 'fa\\nnuc' is not"),
                       MachineError);
}
