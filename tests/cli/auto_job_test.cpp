// `patches: auto` through the real binary: detection on an exact envelope, the whole-surface cover
// in report.json, detected-job.yaml fitting the same patch again, and the job errors of cover:.
#include <doctest/doctest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "postproc/apt.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// An exact envelope of a cone along an arc (paper Fig. 15) and a `patches: auto` job on it.
std::string auto_job(const test::ScratchDir& dir, const std::string& extra) {
  REQUIRE(test::run_flankcam("envelope --profile cone --motion arc --grid-s 40 --grid-t 120 --out " + dir.file("env"), dir)
              .code == 0);
  test::write_text(dir.file("job.yaml"),
                   "surface: env/envelope.obj\ntool: {shape: cone}\ntolerance: 0.05\nfeed: 800\n" + extra + "patches: auto\n");
  return dir.file("job.yaml");
}

// `flankcam <command>` of dir's job.yaml into dir/out, which must succeed: its report.json.
nlohmann::json job_report(const test::ScratchDir& dir, const std::string& command) {
  const auto r = test::run_flankcam(command + " " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  return nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
}
}  // namespace

TEST_CASE("flankcam fit with patches: auto covers an exact envelope with one patch and writes a job that fits it again" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("auto-fit");
  const std::string job = auto_job(dir, "cover: {coverage: 0.95, max_patches: 3}\n");
  const auto r = test::run_flankcam("fit " + job + " --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK(r.err.find("detect: ") != std::string::npos);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& cover = report["cover"];
  CHECK(cover["patches"] == 1);
  CHECK(double(cover["coverage"]) >= 0.95);
  CHECK(cover["stop"] == "coverage reached");
  CHECK(double(cover["overcut_mm"]) <= 0.05);
  REQUIRE(report["patches"].size() == 1);
  const auto& patch = report["patches"][0];
  CHECK(patch["name"] == "auto-1");
  CHECK(patch["init"] == "lines");
  CHECK(double(patch["eps_opt_mm"]) < 0.05);
  // One patch: the union is that patch, so the two coverages agree.
  CHECK(double(patch["coverage"]) == doctest::Approx(double(cover["coverage"])).epsilon(0.01));

  // detected-job.yaml is a job with the patch as init: lines; it fits the same patch again.
  const std::string detected = test::read_text(dir.file("out/detected-job.yaml"));
  CHECK(detected.find("init: lines") != std::string::npos);
  CHECK(detected.find("feed: 800") != std::string::npos);
  const auto again = test::run_flankcam("fit " + dir.file("out/detected-job.yaml") + " --out " + dir.file("again"), dir);
  INFO(again.err);
  REQUIRE(again.code == 0);
  const auto report2 = nlohmann::json::parse(test::read_text(dir.file("again/report.json")));
  CHECK_FALSE(report2.contains("cover"));
  REQUIRE(report2["patches"].size() == 1);
  const auto& patch2 = report2["patches"][0];
  CHECK(patch2["name"] == "auto-1");
  CHECK(std::abs(double(patch2["coverage"]) - double(cover["coverage"])) <= 0.01);
  CHECK(double(patch2["eps_opt_mm"]) < 0.05);
  // The same tool within a few microns.
  CHECK(double(patch2["tool"]["diameter_max"]) == doctest::Approx(double(patch["tool"]["diameter_max"])).epsilon(0.01));
}

TEST_CASE("patches: auto job errors name the file, line and key and write nothing") {
  test::ScratchDir dir("auto-errors");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const struct {
    const char* yaml;
    const char* message;
  } cases[] = {
      {"surface: s.obj\ncover: {coverage: 0.9}\npatches:\n  - {name: p, init: line, line: [0, 0, 0, 0, 0, 1]}\n",
       "job.yaml:2: cover: only with patches: auto"},
      {"surface: s.obj\ncover: {coverage: 1.5}\npatches: auto\n", "job.yaml:2: cover.coverage: must be in (0, 1], got 1.5"},
      {"surface: s.obj\ncover: {coverage: 0}\npatches: auto\n", "job.yaml:2: cover.coverage: must be in (0, 1], got 0"},
      {"surface: s.obj\ncover: {max_patches: 33}\npatches: auto\n", "job.yaml:2: cover.max_patches:"},
      {"surface: s.obj\ncover: {patches: 3}\npatches: auto\n", "job.yaml:2: cover.patches: unknown key"},
      {"surface: s.obj\npatches: automatic\n", "job.yaml:2: patches: expected a list of at least one patch, or auto"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.yaml);
    test::write_text(dir.file("job.yaml"), c.yaml);
    const auto r = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
    CHECK(r.code == 2);
    CHECK(r.err.find(c.message) != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.file("out")));
  }
}

TEST_CASE("patches: auto that finds no patch: fit and run exit 4 with one line and write nothing") {
  // One triangle: no seed line fits, so detection has no patch. Before, fit and run wrote a report of
  // "0 patches" and exited 0, as if the surface had been machined.
  test::ScratchDir dir("auto-none");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  test::write_text(dir.file("job.yaml"), "surface: s.obj\ntolerance: 0.01\nmachine: xyzac-trt\npatches: auto\n");
  for (const char* command : {"fit", "run"}) {
    CAPTURE(command);
    const auto r = test::run_flankcam(std::string(command) + " " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
    CHECK(r.code == 4);
    CHECK(r.err.find("flankcam: refused: patches: auto: no patch machines any of the surface within 0.01 mm (0 candidate "
                     "motions fitted); nothing written") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.file("out")));
  }
}

TEST_CASE("flankcam run of examples/auto posts the detected patch and reports the whole surface" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("auto-run");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/auto/job.yaml";
  const auto r = test::run_flankcam("run " + job + " --out " + dir.file("out") + " --threads 2", dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  CHECK(report["cover"]["patches"] == report["patches"].size());
  CHECK(double(report["cover"]["coverage"]) >= 0.95);
  REQUIRE(report["patches"].size() >= 1);
  CHECK(report["patches"][0]["collisions"].empty());
  CHECK(std::filesystem::exists(dir.file("out/auto-1.mpf")));
  CHECK(test::read_text(dir.file("out/report.html")).find("Whole surface: ") != std::string::npos);
  // The whole surface's pictures: which patch machines each point, and the union's deviation.
  const std::string html = test::read_text(dir.file("out/report.html"));
  CHECK(html.find("Which patch machines each point of the design surface") != std::string::npos);
  CHECK(test::read_text(dir.file("out/surface-patches.svg")).find(">auto-1</text>") != std::string::npos);
  CHECK(test::read_text(dir.file("out/surface-deviation.svg")).find(">machined by no patch</text>") != std::string::npos);
  // The same detection at one thread: detected-job.yaml byte for byte.
  const auto r1 = test::run_flankcam("run " + job + " --out " + dir.file("one") + " --threads 1", dir);
  REQUIRE(r1.code == 0);
  CHECK(test::read_text(dir.file("one/detected-job.yaml")) == test::read_text(dir.file("out/detected-job.yaml")));
  CHECK(test::read_text(dir.file("one/auto-1.mpf")) == test::read_text(dir.file("out/auto-1.mpf")));
}

TEST_CASE("patches: auto on the bundled blade stands every tool tip-down in the work frame and posts it on a head machine" * doctest::test_suite("heavy")) {
  // Detection knows no machine: a patch found with its tip at the top would need the head upside
  // down ("rotary axis B would need -172 deg"). The pipeline turns such a patch end for end.
  test::ScratchDir dir("auto-blade");
  const std::string blade = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj";
  test::write_text(dir.file("job.yaml"), "surface: " + blade +
                                             "\ntool: {shape: general}\ntolerance: 0.015\n"
                                             "holder: {shank_length: 20, shank_diameter: 8, length: 40, diameter: 25, "
                                             "diameter_far: 40}\nmachine: xyzbc-head-table\npost: {dialects: [iso]}\n"
                                             "patches: auto\n");
  const auto report = job_report(dir, "run");
  CHECK(double(report["cover"]["coverage"]) >= 0.95);
  REQUIRE(report["patches"].size() >= 1);
  for (const auto& patch : report["patches"]) {
    CAPTURE(std::string(patch["name"]));
    CHECK(patch["programs"].size() == 1);
    for (const auto& row : patch["axis"]) CHECK(double(row[5]) > double(row[2]));  // b above a: holder up
  }
}

TEST_CASE("the README's main job (examples/auto/blade.yaml) detects, fits and posts the blade without lines, and verify passes it" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("auto-main");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/auto/blade.yaml";
  const auto r = test::run_flankcam("run " + job + " --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  CHECK(double(report["cover"]["coverage"]) >= 0.95);
  CHECK(double(report["cover"]["overcut_mm"]) <= 0.01);
  REQUIRE(report["patches"].size() >= 1);
  CHECK(report["patches"].size() <= 4);
  std::string programs;
  for (const auto& patch : report["patches"]) {
    CAPTURE(std::string(patch["name"]));
    CHECK(patch["collisions"].empty());
    REQUIRE(patch["programs"].size() == 1);
    programs += " " + dir.file("out/" + std::string(patch["programs"][0]["file"]));
  }
  // The programs, read back and simulated through the machine against the blade: clean.
  const auto v = test::run_flankcam("verify --job " + job + programs + " --out " + dir.file("verify"), dir);
  INFO(v.err);
  CHECK(v.code == 0);
}

TEST_CASE("patches: auto with a floor as the part: the tool's tip is brought onto the floor" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("auto-floor");
  // test::leaning_flank standing on its floor, the part. Without the floor's pull the detected tool's tip
  // floated 0.23-0.33 mm above the floor, the flank's bottom row out of its reach.
  write_obj(dir.file("flank.obj"), test::leaning_flank());
  write_obj(dir.file("floor.obj"), test::floor_under_leaning_flank());
  test::write_text(dir.file("job.yaml"),
                   "surface: flank.obj\npart: floor.obj\ncheck_tolerance: 0.005\ntool: {shape: cone}\ntolerance: 0.02\n"
                   "patches: auto\n");
  const auto report = job_report(dir, "fit");
  CHECK(double(report["cover"]["coverage"]) >= 0.95);
  REQUIRE(report["patches"].size() == 1);
  const auto& p = report["patches"][0];
  CHECK(double(p["check_surface"]["worst_intrusion_mm"]) <= 0.0);
  // The flat end's lowest rim point at every cutting pose of the CL-data (tip point, unit axis):
  // on the floor, within the check tolerance into it and the tolerance above it.
  const double radius = p["radius"][0];
  const ClProgram cl = read_apt(dir.file("out/auto-1.apt"));
  double low = INFINITY, high = -INFINITY;
  int poses = 0;
  REQUIRE(cl.moves.size() == p["axis"].size() + 4);  // approach, lead-in, the poses, lead-out, retract
  for (size_t k = 2; k + 2 < cl.moves.size(); ++k) {
    const ClMove& m = cl.moves[k];
    CHECK_FALSE(m.rapid);
    const double rim = test::lowest_rim_z(m.pose.tip, m.pose.axis, radius);
    low = std::min(low, rim), high = std::max(high, rim);
    ++poses;
  }
  MESSAGE(poses, " cutting poses, the flat end's lowest rim point z ", low, " to ", high, " mm, tip radius ", radius, " mm");
  CHECK(poses > 50);
  CHECK(low >= -0.005 - 1e-3);
  CHECK(high <= 0.02);
}

TEST_CASE("patches: auto with a catalogue tool (examples/auto/blade-catalogue.yaml): the bundled blade covered by the bought taper, compared with a custom tool, verified" * doctest::test_suite("heavy")) {
  // The catalogue's Ø10 1° taper, 65 mm long, held through detection: only motions are fitted.
  // Measured: 1 patch, 100% within 0.01 mm, ε 0.0061 mm (the best custom tool on the same lines:
  // 0.0057 mm, Ø10.1-12.3), verify clean, 6 s.
  test::ScratchDir dir("auto-catalogue");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/auto/blade-catalogue.yaml";
  const auto r = test::run_flankcam("run " + job + " --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  CHECK(report["cover"]["tool"]["policy"] == "catalogue");
  CHECK(report["cover"]["tool"]["name"] == "taper-d10-1deg-l65");
  CHECK(double(report["cover"]["coverage"]) >= 0.95);
  CHECK(double(report["cover"]["overcut_mm"]) <= 0.01);
  REQUIRE(report["patches"].size() >= 1);
  std::string programs;
  for (const auto& patch : report["patches"]) {
    CAPTURE(std::string(patch["name"]));
    // The tool as bought: 65 mm long, Ø10 at the tip, widening by 1° a side.
    CHECK(double(patch["tool"]["length"]) == doctest::Approx(65).epsilon(1e-6));
    CHECK(double(patch["tool"]["diameter_min"]) == doctest::Approx(10).epsilon(1e-3));
    CHECK(double(patch["tool"]["diameter_max"]) == doctest::Approx(10 + 2 * 65 * std::tan(M_PI / 180)).epsilon(1e-3));
    // The best custom tool fitted to the same detected lines, beside it.
    const auto& cmp = patch["compare_custom_tool"];
    REQUIRE(cmp.is_object());
    CHECK(double(cmp["catalogue"]["eps_mm"]) == doctest::Approx(double(patch["eps_opt_mm"])));
    CHECK(double(cmp["custom"]["coverage"]) > 0.5);
    CHECK(double(cmp["custom"]["length"]) > 0);
    CHECK(patch["collisions"].empty());
    REQUIRE(patch["programs"].size() == 1);
    programs += " " + dir.file("out/" + std::string(patch["programs"][0]["file"]));
  }
  // detected-job.yaml keeps the catalogue tool with the detected lines and runs again.
  const std::string detected = test::read_text(dir.file("out/detected-job.yaml"));
  CHECK(detected.find("tool: {catalogue: taper-d10-1deg-l65}") != std::string::npos);
  const auto again = test::run_flankcam("fit " + dir.file("out/detected-job.yaml") + " --out " + dir.file("again"), dir);
  INFO(again.err);
  CHECK(again.code == 0);
  const auto v = test::run_flankcam("verify --job " + job + programs + " --out " + dir.file("verify"), dir);
  INFO(v.err);
  CHECK(v.code == 0);
}
