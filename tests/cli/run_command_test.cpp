#include <doctest/doctest.h>

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <sstream>
#include <nlohmann/json.hpp>

#include "core/blade.h"
#include "kinematics/machine.h"
#include "postproc/apt.h"
#include "postproc/gcode.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

// A small twisted blade side from `flankcam blade`, and a run job for it.
std::string blade_job(const test::ScratchDir& dir, const std::string& machine, const std::string& dialects, int patches) {
  REQUIRE(test::run_flankcam("blade --grid-chord 40 --grid-span 20 --out " + dir.file("blade"), dir).code == 0);
  BladeOptions o;
  o.grid_chord = 40, o.grid_span = 20;
  const auto lines = blade_lines(make_blade(o), patches, 5, 6, 1);
  std::string job = fmt::format(R"(surface: blade/blade.obj
tool: {{shape: cone}}
tolerance: 0.015
sampling: {{s: 20, t: 60}}
holder: {{shank_length: 20, shank_diameter: 8, length: 40, diameter: 25}}
feed: 600
machine: {}
post: {{dialects: [{}]}}
patches:
)",
                                machine, dialects);
  for (size_t k = 0; k < lines.size(); ++k) {
    job += fmt::format("  - name: p{}\n    init: lines\n    lines:\n", k + 1);
    for (const auto& l : lines[k]) job += fmt::format("      - [{}]\n", fmt::join(l, ", "));
  }
  test::write_text(dir.file("job.yaml"), job);
  return dir.file("job.yaml");
}

double angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

}  // namespace

TEST_CASE("flankcam run end to end: the program, back-simulated through the machine, follows the fitted motion" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("run");
  const std::string job = blade_job(dir, "xyzac-trt", "linuxcnc, iso", 1);
  const auto r = test::run_flankcam("run " + job + " --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& patch = report["patches"][0];
  CHECK(double(patch["eps_opt_mm"]) < 0.015);
  REQUIRE(patch["programs"].size() == 2);
  const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");

  // The fitted motion: report rows (mm) at the samples t_i, tip = a, axis = b - a.
  std::vector<ToolPose> fitted;
  for (const auto& row : patch["axis"]) {
    const Eigen::Vector3d a(row[0], row[1], row[2]), b(row[3], row[4], row[5]);
    fitted.push_back({a, (b - a).normalized()});
  }
  for (const auto& [file_, dialect] : {std::pair{"p1.ngc", Dialect::LinuxCnc}, std::pair{"p1.nc", Dialect::Iso}}) {
    const std::string file = file_;  // a copy: CAPTURE's lambda may not name a structured binding (C++17)
    CAPTURE(file);
    const auto points = parse_nc(test::read_text(dir.file(std::string("out/") + file)), dialect, {"A", "C"}, file);
    // Every fitted pose is a program point, in order (4 decimals of mm and degrees).
    size_t next = 0;
    std::vector<ToolPose> sim;
    std::vector<Joints> joints;
    for (const NcPoint& p : points) {
      if (p.rapid || p.known != AxesAll) continue;
      sim.push_back(programmed_pose(m, p.at, 0));
      joints.push_back(p.at);
      if (next < fitted.size() && (sim.back().tip - fitted[next].tip).norm() < 1e-3 && angle(sim.back().axis, fitted[next].axis) < 1e-5)
        ++next;
    }
    CHECK(next == fitted.size());
    // Inside every feed block the machine's joint interpolation stays within the linearisation
    // tolerance (0.005 mm) of the fitted motion between its samples.
    double worst = 0;
    for (size_t i = 1; i < joints.size(); ++i)
      for (double f : {0.25, 0.5, 0.75}) {
        Joints q;
        q.linear = (1 - f) * joints[i - 1].linear + f * joints[i].linear;
        for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * joints[i - 1].rotary[k] + f * joints[i].rotary[k];
        const Eigen::Vector3d tip = forward(m, q, 0).tip;
        double best = 1e9;  // distance to the polyline of fitted tips (and the lead-in/out along the axes)
        for (size_t k = 0; k + 1 < fitted.size(); ++k) {
          const Eigen::Vector3d a = fitted[k].tip, b = fitted[k + 1].tip;
          const double s = std::clamp((tip - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
          best = std::min(best, (a + s * (b - a) - tip).norm());
        }
        // The lead-out runs off the surface along its normal: the line from the last fitted tip to
        // where the program's last feed block ends (the lead-in is approached by a rapid).
        const double lead_in = (tip - fitted.front().tip).cross(fitted.front().axis).norm();
        const Eigen::Vector3d out_dir = (sim.back().tip - fitted.back().tip).normalized();
        const double lead_out = (tip - fitted.back().tip).cross(out_dir).norm();
        worst = std::max(worst, std::min({best, lead_in, lead_out}));
      }
    MESSAGE(file << ": " << fitted.size() << " fitted poses reached; joint interpolation within " << worst << " mm");
    CHECK(worst < 0.005 + 2e-4);
  }
  // CL CSV: each pass row's contact point lies on the tool: its distance from the axis is the
  // tool's radius at its height, within the fitted error.
  std::vector<Eigen::Vector2d> profile;
  for (const auto& zr : patch["tool"]["profile"]) profile.emplace_back(double(zr[0]), double(zr[1]));
  std::istringstream csv(test::read_text(dir.file("out/p1-cl.csv")));
  std::string row;
  int contacts = 0;
  double worst_contact = 0;
  while (std::getline(csv, row)) {
    std::vector<std::string> c;
    std::istringstream cells(row);
    for (std::string cell; std::getline(cells, cell, ',');) c.push_back(cell);
    if (c.size() != 12 || c[1] != "feed" || c[8].empty()) continue;
    const Eigen::Vector3d tip(std::stod(c[2]), std::stod(c[3]), std::stod(c[4])), k(std::stod(c[5]), std::stod(c[6]), std::stod(c[7]));
    const Eigen::Vector3d q = Eigen::Vector3d(std::stod(c[8]), std::stod(c[9]), std::stod(c[10])) - tip;
    const double z = q.dot(k), rho = (q - z * k).norm();
    size_t j = 1;
    while (j + 1 < profile.size() && profile[j].x() < z) ++j;
    const double f = std::clamp((z - profile[j - 1].x()) / (profile[j].x() - profile[j - 1].x()), 0.0, 1.0);
    worst_contact = std::max(worst_contact, std::abs(rho - ((1 - f) * profile[j - 1].y() + f * profile[j].y())));
    ++contacts;
  }
  CHECK(contacts == int(fitted.size()));
  CHECK(worst_contact < 0.015);

  // The report people look at: offline, one picture of each kind per patch.
  const std::string html = test::read_text(dir.file("out/report.html"));
  CHECK(html.find("<svg") != std::string::npos);
  size_t svgs = 0;
  for (size_t at = html.find("<svg"); at != std::string::npos; at = html.find("<svg", at + 1)) ++svgs;
  CHECK(svgs == 3);
  CHECK(html.find("src=\"http") == std::string::npos);
  // Scripts only in the 3D view (three.js and the page's own, inlined), none loaded from elsewhere.
  CHECK(html.find("<script") > html.find("<section id=\"flankcam-view\">"));
  CHECK(html.find(" src=") == std::string::npos);
  for (const char* f : {"p1-deviation.svg", "p1-tool.svg", "p1-angles.svg", "p1-tool.dxf", "p1-tool.stl", "p1.apt"})
    CHECK(std::filesystem::exists(dir.file(std::string("out/") + f)));
}

TEST_CASE("flankcam run: same input, same output, byte for byte at --threads 1 and 2" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("run-repeat");
  const std::string job = blade_job(dir, "xyzac-trt", "linuxcnc", 3);
  REQUIRE(test::run_flankcam("run " + job + " --out " + dir.file("a") + " --threads 2", dir).code == 0);
  REQUIRE(test::run_flankcam("run " + job + " --out " + dir.file("b") + " --threads 1", dir).code == 0);
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.file("a"))) {
    const std::string name = e.path().filename().string();
    CAPTURE(name);
    if (name == "report.html") continue;  // it holds the output path
    if (name == "report.json") {
      // Every number but the timings, to the last digit (was: a mean differed in the 14th digit).
      nlohmann::json ra = nlohmann::json::parse(test::read_text(e.path().string()));
      nlohmann::json rb = nlohmann::json::parse(test::read_text(dir.file("b/" + name)));
      for (nlohmann::json* r : {&ra, &rb})
        for (auto& p : (*r)["patches"]) p.erase("seconds");
      CHECK(ra.dump() == rb.dump());
      continue;
    }
    CHECK(test::read_text(e.path().string()) == test::read_text(dir.file("b/" + name)));
    ++files;
  }
  CHECK(std::filesystem::exists(dir.file("a/all-patches.ngc")));
  CHECK(files > 30);
}

TEST_CASE("flankcam run: an unreachable pose or a bad key ends the run with one line and no files") {
  test::ScratchDir dir("run-errors");
  // A trunnion whose A table tilts only +-2 degrees cannot reach the blade's axes.
  std::string machine = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const size_t at = machine.find("limits: [-120, 30]");
  REQUIRE(at != std::string::npos);
  machine.replace(at, 18, "limits: [-2, 2]");
  test::write_text(dir.file("stiff.yaml"), machine);
  const std::string job = blade_job(dir, "stiff.yaml", "linuxcnc", 1);
  auto r = test::run_flankcam("run " + job + " --out " + dir.file("out") + " --quiet", dir);
  CHECK(r.code == 2);
  CHECK(r.err.find("patch 'p1': pose ") != std::string::npos);
  CHECK(r.err.find("is out of reach") != std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
  CHECK((!std::filesystem::exists(dir.file("out")) || std::filesystem::is_empty(dir.file("out"))));

  std::string text = test::read_text(job);
  test::write_text(dir.file("nomachine.yaml"), text.substr(0, text.find("machine:")) + text.substr(text.find("patches:")));
  r = test::run_flankcam("run " + dir.file("nomachine.yaml") + " --out " + dir.file("out2"), dir);
  CHECK(r.code == 2);
  CHECK(r.err.find("machine: missing") != std::string::npos);
  test::write_text(dir.file("baddialect.yaml"), text.replace(text.find("[linuxcnc]"), 10, "[linuxcnc, klingon]"));
  r = test::run_flankcam("run " + dir.file("baddialect.yaml") + " --out " + dir.file("out3"), dir);
  CHECK(r.code == 2);
  CHECK(r.err.find("baddialect.yaml:8: post.dialects[1]: dialect: 'klingon' is not one of") != std::string::npos);
  CHECK(!std::filesystem::exists(dir.file("out2")));
  CHECK(!std::filesystem::exists(dir.file("out3")));
}

TEST_CASE("flankcam run: a gouging patch gets no program, exit 4, and the report says so" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("run-collide");
  std::string job = test::read_text(blade_job(dir, "xyzac-trt", "linuxcnc", 3));
  // At 0.5 um no cone fits the twisted blade: the cutter's overcut beyond the tolerance is a gouge.
  job.replace(job.find("tolerance: 0.015"), 16, "tolerance: 0.0005");
  test::write_text(dir.file("fat.yaml"), job);
  const auto r = test::run_flankcam("run " + dir.file("fat.yaml") + " --out " + dir.file("out") + " --quiet", dir);
  CHECK(r.code == 4);
  CHECK(r.err.find("no program was written for them") != std::string::npos);
  CHECK(!std::filesystem::exists(dir.file("out/p1.ngc")));
  CHECK(std::filesystem::exists(dir.file("out/report.html")));
  CHECK(test::read_text(dir.file("out/report.html")).find("No program was written for this patch") != std::string::npos);
}

TEST_CASE("the bundled examples are what the generators make, and their jobs read") {
  test::ScratchDir dir("examples");
  REQUIRE(test::run_flankcam("blade --out " + dir.file("blade"), dir).code == 0);
  const std::string ex = std::string(FLANKCAM_SOURCE_DIR) + "/examples/";
  CHECK(test::read_text(dir.file("blade/blade.obj")) == test::read_text(ex + "blade/blade.obj"));
  CHECK(test::read_text(dir.file("blade/lines.yaml")) == test::read_text(ex + "blade/lines.yaml"));
}

TEST_CASE("flankcam run: the setup places the part on the machine, programs follow while CL-data stays in part coordinates" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("run-setup");
  std::string job = test::read_text(blade_job(dir, "xyzac-trt", "linuxcnc", 1));
  job.replace(job.find("post: {dialects: [linuxcnc]}"), 28,
              "post: {dialects: [linuxcnc], setup: {rotate: [0, 0, 90], translate: [5, -3, 10]}}");
  test::write_text(dir.file("placed.yaml"), job);
  const auto r = test::run_flankcam("run " + dir.file("placed.yaml") + " --out " + dir.file("out") + " --quiet", dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& row = report["patches"][0]["axis"][0];
  const Eigen::Vector3d a(row[0], row[1], row[2]), b(row[3], row[4], row[5]);
  // Work frame: rotated 90 degrees about Z, then moved.
  const Eigen::Vector3d tip = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()) * a + Eigen::Vector3d(5, -3, 10);
  const Eigen::Vector3d axis = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()) * (b - a).normalized();
  const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const auto points = parse_nc(test::read_text(dir.file("out/p1.ngc")), Dialect::LinuxCnc, {"A", "C"}, "p1.ngc");
  bool found = false;
  for (const NcPoint& p : points) {
    if (p.rapid || p.known != AxesAll) continue;
    const ToolPose s = programmed_pose(m, p.at, 0);
    found = found || ((s.tip - tip).norm() < 1e-3 && angle(s.axis, axis) < 1e-5);
  }
  CHECK(found);
  CHECK(read_apt(dir.file("out/p1.apt")).moves[2].pose.tip.isApprox(a, 1e-6));  // CL-data: part frame
  CHECK(test::read_text(dir.file("out/p1.ngc")).find("work frame = part rotated X 0 Y 0 Z 90 deg, moved by [5, -3, 10] mm") !=
        std::string::npos);

  job.replace(job.find("rotate: [0, 0, 90]"), 18, "rotate: [0, 90]");
  test::write_text(dir.file("bad.yaml"), job);
  const auto bad = test::run_flankcam("run " + dir.file("bad.yaml") + " --out " + dir.file("out2"), dir);
  CHECK(bad.code == 2);
  CHECK(bad.err.find("bad.yaml:8: post.setup.rotate: expected 3 numbers") != std::string::npos);
}
