// `flankcam run` with the tool keys of issue 15: a shared custom tool within shop limits, and a
// catalogue tool compared with the best custom one (the bundled blade examples).
#include <doctest/doctest.h>

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/test_util.h"

using namespace flankcam;

namespace {
int count(const std::string& text, const std::string& word) {
  int n = 0;
  for (size_t at = text.find(word); at != std::string::npos; at = text.find(word, at + 1)) ++n;
  return n;
}
}  // namespace

TEST_CASE("flankcam run of examples/blade/job-shared-tool.yaml: one tool within its limits, one tool change, a grinding sheet" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("shared-tool-run");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/job-shared-tool.yaml";
  const test::RunResult r = test::run_flankcam("run " + job + " --quiet --out " + dir.file("out"), dir);
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  REQUIRE(report["patches"].size() == 3);
  const std::string tool = test::read_text(dir.file("out/blade-1-tool.csv"));
  for (const auto& p : report["patches"]) {
    const std::string name = p["name"];
    CAPTURE(name);
    CHECK(p["tool"]["shared"] == true);
    CHECK(p["tool"]["constraints"]["met"] == true);
    CHECK(p["tool"]["diameter_min"].get<double>() >= 6 - 1e-6);
    CHECK(p["tool"]["diameter_max"].get<double>() <= 20 + 1e-6);
    MESSAGE(name << ": eps " << p["eps_opt_mm"] << " mm, coverage " << p["coverage"] << ", D " << p["tool"]["diameter_min"]
                 << ".." << p["tool"]["diameter_max"]);
    // The same meridian in every tool file (apart from the comment naming the patch).
    const std::string mine = test::read_text(dir.file("out/" + name + "-tool.csv"));
    CHECK(mine.substr(mine.find('\n')) == tool.substr(tool.find('\n')));
    const std::string sheet = test::read_text(dir.file("out/" + name + "-tool-sheet.csv"));
    CHECK(sheet.find("shared by every patch") != std::string::npos);
    CHECK(sheet.find("tolerance_mm,0.015000") != std::string::npos);
    CHECK(std::filesystem::exists(dir.file("out/" + name + ".nc")));
  }
  // All patches run with one tool: a single tool change (M6) in the program of all patches.
  CHECK(count(test::read_text(dir.file("out/all-patches.nc")), "M6") == 1);
}

TEST_CASE("flankcam run of examples/blade/job-catalogue.yaml: the catalogue taper against the best custom tool" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("catalogue-run");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/job-catalogue.yaml";
  const test::RunResult r = test::run_flankcam("run " + job + " --quiet --out " + dir.file("out"), dir);
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  for (const auto& p : report["patches"]) {
    const std::string name = p["name"];
    CAPTURE(name);
    CHECK(p["tool"]["catalogue"]["name"] == "taper-d10-1deg-l65");
    // The tool is the catalogue's: Ø10 at the tip, 1 deg, 65 mm (Ø12.27 at the shank end).
    CHECK(p["tool"]["diameter_min"].get<double>() == doctest::Approx(10).epsilon(2e-3));
    CHECK(p["tool"]["diameter_max"].get<double>() == doctest::Approx(10 + 2 * 65 * std::tan(M_PI / 180)).epsilon(2e-3));
    CHECK(p["tool"]["length"].get<double>() == doctest::Approx(65).epsilon(2e-3));
    const auto& cmp = p["compare_custom_tool"];
    MESSAGE(name << ": catalogue eps " << cmp["catalogue"]["eps_mm"] << " mm, coverage " << cmp["catalogue"]["coverage"]
                 << "; custom eps " << cmp["custom"]["eps_mm"] << " mm, coverage " << cmp["custom"]["coverage"]);
    CHECK(cmp["custom"]["eps_mm"].get<double>() > 0);
    CHECK(cmp["catalogue"]["eps_mm"] == p["eps_opt_mm"]);
    CHECK(!std::filesystem::exists(dir.file("out/" + name + "-tool-sheet.csv")));  // bought, not ground
  }
  CHECK(count(test::read_text(dir.file("out/all-patches.nc")), "M6") == 1);
  // One tool, named after the first patch, cuts all three: verify compares each section with its own
  // patch's CL-data (it compared all of them with blade-1.apt: 202 cutting blocks "off" by up to 1.1 mm).
  const test::RunResult v =
      test::run_flankcam("verify --job " + job + " " + dir.file("out/all-patches.nc") + " --out " + dir.file("verify"), dir);
  CAPTURE(v.err);
  CHECK(v.code == 0);
  const nlohmann::json vj = nlohmann::json::parse(test::read_text(dir.file("verify/verify.json")));
  const auto& cl = vj["programs"][0]["cl_data"];
  CAPTURE(cl.dump());
  CHECK(cl["files"].size() == 3);
  CHECK(cl["feed_blocks_compared"].get<int>() > 250);
  CHECK(cl["off_cl_data"].size() == 0);
}

TEST_CASE("a catalogue patch on which no custom tool can be fitted keeps its fit: the comparison says why, the job goes on") {
  // The catalogue's Ø8 25 mm cylinder along the bundled blade's lower edge, its tip 3.3 mm below the
  // blade (lines from a detection of it). The catalogue fit is good (ε 0.0014 mm); a general custom
  // tool on the same lines folds back at its tip, where no design surface holds it, and is no tool.
  // That comparison used to end the job with the custom fit's error; now report.json says why and
  // the job runs on (exit 4 here: the Ø8 shank, as wide as the cutter, rubs the flank above the cut).
  test::ScratchDir dir("catalogue-no-custom");
  const std::string blade = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj";
  test::write_text(dir.file("job.yaml"),
                   "surface: " + blade +
                       "\ntool: {catalogue: cyl-d8-l25}\ntolerance: 0.01\n"
                       "holder: {shank_length: 20, shank_diameter: 8, length: 40, diameter: 25, diameter_far: 40}\n"
                       "clearance: 1\npatches:\n  - name: low\n    init: lines\n    length: 25\n    lines:\n"
                       "      - [27.204720, 4.644823, -3.285893, 27.185912, 7.727636, 21.523300]\n"
                       "      - [17.196132, 6.917139, -3.725951, 16.861424, 8.791596, 21.201426]\n"
                       "      - [6.665515, 8.223704, -3.549020, 6.121380, 8.772418, 21.438997]\n"
                       "      - [-4.005521, 7.610952, -3.354632, -4.376445, 6.820950, 21.630114]\n"
                       "      - [-9.056903, 6.177625, -3.480467, -9.136712, 4.700263, 21.475753]\n");
  const test::RunResult r = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
  CAPTURE(r.err);
  CHECK((r.code == 0 || r.code == 4));
  CHECK(r.err.find("flankcam: error") == std::string::npos);
  CHECK(r.err.find("patch low: catalogue tool cyl-d8-l25: eps ") != std::string::npos);
  CHECK(r.err.find("no custom tool on the same lines: ") != std::string::npos);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  REQUIRE(report["patches"].size() == 1);
  const auto& p = report["patches"][0];
  CHECK(p["eps_opt_mm"].get<double>() < 0.01);
  CHECK(p["compare_custom_tool"]["catalogue"]["eps_mm"] == p["eps_opt_mm"]);
  const auto& custom = p["compare_custom_tool"]["custom"];
  REQUIRE(custom.contains("failed"));
  CHECK(std::string(custom["failed"]).find("describe no tool") != std::string::npos);
  CHECK(!custom.contains("eps_mm"));
}

TEST_CASE("passes: NAME.apt holds every pass in order, and flankcam verify finds the program on its CL-data" * doctest::test_suite("heavy")) {
  // The program cuts the 0.3 mm pass and then the final one; verify compares every cutting block with
  // NAME.apt, so the APT must hold both (it held the last pass only: 101 blocks "off the CL-data").
  test::ScratchDir dir("passes-verify");
  std::string job = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/job-1-patch.yaml");
  job.replace(job.find("surface: blade.obj"), 18, "surface: " + std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj");
  job.replace(job.find("post: {dialects: [iso, heidenhain]}"), 35, "post: {dialects: [iso]}");
  job += "passes: [{allowance: 0.3}, {allowance: 0}]\n";
  test::write_text(dir.file("job.yaml"), job);
  const test::RunResult r = test::run_flankcam("run " + dir.file("job.yaml") + " --quiet --out " + dir.file("out"), dir);
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  const std::string apt = test::read_text(dir.file("out/blade.apt"));
  const std::string program = test::read_text(dir.file("out/blade.nc"));
  // The CL CSV holds both passes like the APT (a line a move after two header lines): twice the
  // moves of the fit's own CL-data.
  const int csv_moves = count(test::read_text(dir.file("out/blade-cl.csv")), "\n") - 2;
  const int csv_feed = count(test::read_text(dir.file("out/blade-cl.csv")), ",feed,");
  CHECK(count(apt, "GOTO/") >= csv_moves);
  CHECK(csv_feed % 2 == 0);
  const int csv_poses = csv_moves / 2;
  const test::RunResult v = test::run_flankcam(
      "verify --job " + dir.file("job.yaml") + " " + dir.file("out/blade.nc") + " --out " + dir.file("verify"), dir);
  CAPTURE(v.err);
  CHECK(v.code == 0);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("verify/verify.json")));
  const nlohmann::json& cl = report["programs"][0]["cl_data"];
  CHECK(cl["off_cl_data"].empty());
  CHECK(int(cl["feed_blocks_compared"]) > 2 * csv_poses * 9 / 10);  // both passes compared
  CHECK(count(program, "M6") == 1);
}

TEST_CASE("depth_cuts: 3: the program, NAME.apt and NAME-cl.csv hold every level, flankcam verify finds them on the CL-data" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("depth-cuts-verify");
  std::string job = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/job-1-patch.yaml");
  job.replace(job.find("surface: blade.obj"), 18, "surface: " + std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj");
  job.replace(job.find("post: {dialects: [iso, heidenhain]}"), 35, "post: {dialects: [iso]}");
  test::write_text(dir.file("one.yaml"), job);
  test::write_text(dir.file("job.yaml"), job + "depth_cuts: 3\n");
  const test::RunResult one = test::run_flankcam("run " + dir.file("one.yaml") + " --quiet --out " + dir.file("one"), dir);
  const test::RunResult r = test::run_flankcam("run " + dir.file("job.yaml") + " --quiet --out " + dir.file("out"), dir);
  CAPTURE(one.err);
  CAPTURE(r.err);
  REQUIRE(one.code == 0);
  REQUIRE(r.code == 0);
  const std::string program = test::read_text(dir.file("out/blade.nc"));
  const int moves = count(test::read_text(dir.file("one/blade-cl.csv")), "\n") - 2;
  CHECK(count(test::read_text(dir.file("out/blade-cl.csv")), "\n") - 2 == 3 * moves);
  CHECK(count(test::read_text(dir.file("out/blade.apt")), "GOTO/") == 3 * count(test::read_text(dir.file("one/blade.apt")), "GOTO/"));
  for (const char* level : {"DEPTH CUT 1 OF 3", "DEPTH CUT 2 OF 3", "DEPTH CUT 3 OF 3"}) CHECK(program.find(level) != std::string::npos);
  CHECK(count(program, "M6") == 1);
  const test::RunResult v = test::run_flankcam(
      "verify --job " + dir.file("job.yaml") + " " + dir.file("out/blade.nc") + " --out " + dir.file("verify"), dir);
  CAPTURE(v.err);
  CHECK(v.code == 0);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("verify/verify.json")));
  const nlohmann::json& cl = report["programs"][0]["cl_data"];
  CHECK(cl["off_cl_data"].empty());
  MESSAGE("verify: " << cl["feed_blocks_compared"] << " feed blocks compared with the CL-data of 3 levels (" << moves
                     << " moves a level)");
  CHECK(int(cl["feed_blocks_compared"]) > 3 * moves * 9 / 10);  // every level compared
  // The design surface's share: of the vertices the program reaches, and of all of them (the
  // message said "of the design surface" for the first).
  const nlohmann::json& ds = report["programs"][0]["design_surface"];
  const std::string obj = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj");
  const int vertices = count(obj, "\nv ") + (obj.rfind("v ", 0) == 0 ? 1 : 0);
  CHECK(double(ds["coverage"]) == doctest::Approx(double(ds["within_tolerance"]) / double(ds["vertices_reached"])).epsilon(1e-3));
  CHECK(double(ds["share_of_all_vertices"]) == doctest::Approx(double(ds["within_tolerance"]) / vertices).epsilon(1e-3));
  CHECK(double(ds["share_of_all_vertices"]) <= double(ds["coverage"]));

  // Bad values: exit 2, the key and line named, nothing written.
  std::string bad_end = job;
  bad_end.replace(bad_end.find("tool: {shape: general}"), 22, "tool: {shape: general, end: {corner: 0}}");
  const struct {
    std::string yaml, key;
  } bad[] = {{job + "depth_cuts: 0\n", ": depth_cuts: "},
             {job + "depth_cuts: 2.5\n", ": depth_cuts: "},
             {job + "depth_cuts: 51\n", ": depth_cuts: "},
             {bad_end, ": tool.end.corner: must be > 0"}};
  for (const auto& b : bad) {
    CAPTURE(b.yaml);
    test::write_text(dir.file("bad.yaml"), b.yaml);
    const test::RunResult e = test::run_flankcam("run " + dir.file("bad.yaml") + " --quiet --out " + dir.file("bad"), dir);
    CAPTURE(e.err);
    CHECK(e.code == 2);
    CHECK(e.err.find(dir.file("bad.yaml") + ":") != std::string::npos);
    CHECK(e.err.find(b.key) != std::string::npos);
    CHECK(!std::filesystem::exists(dir.file("bad/blade.nc")));
  }
}
