#include <doctest/doctest.h>

#include <fmt/format.h>
#include <omp.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "pipeline/data_dir.h"
#include "pipeline/run.h"
#include "tests/test_util.h"

using namespace flankcam;
namespace fs = std::filesystem;

TEST_CASE("--threads reaches the OpenMP loops of the fit, and the previous count is restored after it") {
  test::ScratchDir dir("threads");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n");
  test::write_text(dir.file("job.yaml"), "surface: s.obj\npatches:\n  - name: p\n    init: line\n    line: [0, 0, 5, 0, 0, 15]\n");
  const int before = omp_get_max_threads();
  for (const int threads : {1, 3}) {
    CAPTURE(threads);
    pipeline::RunOptions o;
    o.threads = threads;
    int seen = 0;
    // The first progress line comes from inside the fit; stop there.
    o.progress = [&](const std::string&) {
      seen = omp_get_max_threads();
      throw std::runtime_error("stop");
    };
    CHECK_THROWS_WITH(pipeline::fit(pipeline::read_job(dir.file("job.yaml")), o), "stop");
    CHECK(seen == threads);
    CHECK(omp_get_max_threads() == before);
  }
  pipeline::RunOptions o;
  o.threads = 0;
  CHECK(o.validate() == "threads: 1 .. 256");
}

TEST_CASE("from_work undoes to_work for seeded random setups and poses") {
  std::mt19937 rng;
  std::uniform_real_distribution<double> deg(-180, 180), mm(-100, 100);
  double worst_tip = 0, worst_axis = 0;
  for (int k = 0; k < 200; ++k) {
    pipeline::PostJob setup;
    setup.setup_rotate_deg = {deg(rng), deg(rng), k % 10 == 0 ? 0.0 : deg(rng)};
    setup.setup_translate_mm = {mm(rng), mm(rng), mm(rng)};
    const ToolPose p{{mm(rng), mm(rng), mm(rng)}, Eigen::Vector3d(mm(rng), mm(rng), mm(rng)).normalized()};
    const ToolPose back = pipeline::from_work(setup, pipeline::to_work(setup, p));
    worst_tip = std::max(worst_tip, (back.tip - p.tip).norm());
    worst_axis = std::max(worst_axis, (back.axis - p.axis).norm());
  }
  CHECK(worst_tip < 1e-10);
  CHECK(worst_axis < 1e-12);
}

TEST_CASE("the shipped machines are found from the build tree") {
  const fs::path dir = pipeline::machines_dir();
  CHECK(fs::is_regular_file(dir / "xyzac-trt.yaml"));
  CHECK(pipeline::tools_dir() == dir / "tools");
}

TEST_CASE("cmake --install: the installed flankcam runs the bundled example from another folder" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("install");
  const std::string prefix = dir.file("prefix");
  const std::string install = std::string("\"") + CMAKE_COMMAND + "\" --install \"" + FLANKCAM_BUILD_DIR + "\" --prefix \"" +
                              prefix + "\" > " + dir.file("install.log") + " 2>&1";
  const int installed = std::system(install.c_str());
  INFO(test::read_text(dir.file("install.log")));
  REQUIRE(WIFEXITED(installed));
  REQUIRE(WEXITSTATUS(installed) == 0);
  REQUIRE(fs::is_regular_file(prefix + "/share/flankcam/machines/xyzac-trt.yaml"));
  // From an unrelated folder, the job by absolute path, the machine by its shipped name.
  fs::create_directories(dir.file("elsewhere"));
  const std::string run = "cd \"" + dir.file("elsewhere") + "\" && \"" + prefix + "/bin/flankcam\" run \"" + FLANKCAM_SOURCE_DIR +
                          "/examples/conical-tool/job.yaml\" --out out --quiet > run.log 2>&1";
  const int ran = std::system(run.c_str());
  INFO(test::read_text(dir.file("elsewhere/run.log")));
  REQUIRE(WIFEXITED(ran));
  CHECK(WEXITSTATUS(ran) == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("elsewhere/out/report.json")));
  // The machine came from the installed share/flankcam, not from the source tree.
  const std::string machine = report["machine"]["file"];
  CHECK(machine == fs::weakly_canonical(prefix + "/share/flankcam/machines/xyzac-trt.yaml").string());
  CHECK(fs::exists(dir.file("elsewhere/out/cone-3.ngc")));
}

TEST_CASE("post.setup: auto turns a part over when its flank opens downwards (no upright setup reaches it)" * doctest::test_suite("heavy")) {
  // The conical-tool blade and cone-1's lines turned 180 deg about X: the tools point down, xyzac-trt's
  // A (-120..30 deg) cannot tilt the table that far (the HECC diffuser, hub on top, was refused with
  // "no candidate rotation reaches every pose"). auto must turn the part over.
  test::ScratchDir dir("setup-flip");
  const auto lines_of = [](const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) out.push_back(l);
    return out;
  };
  std::string obj;
  for (const std::string& line : lines_of(test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj"))) {
    if (line.rfind("v ", 0) != 0) {
      obj += line + "\n";
      continue;
    }
    double x, y, z;
    REQUIRE(std::sscanf(line.c_str(), "v %lf %lf %lf", &x, &y, &z) == 3);
    obj += fmt::format("v {} {} {}\n", x, -y, -z);
  }
  test::write_text(dir.file("blade.obj"), obj);
  std::string job = "surface: blade.obj\n";
  for (const std::string& line : lines_of(test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/conical-tool/job.yaml"))) {
    if (line.rfind("surface:", 0) == 0 || line.rfind("#", 0) == 0) continue;
    if (line.find("name: cone-2") != std::string::npos) break;  // one patch
    std::array<double, 6> v{};
    if (std::sscanf(line.c_str(), " - [%lf, %lf, %lf, %lf, %lf, %lf]", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]) == 6) {
      job += fmt::format("      - [{}, {}, {}, {}, {}, {}]\n", v[0], -v[1], -v[2], v[3], -v[4], -v[5]);
      continue;
    }
    job += (line.rfind("post:", 0) == 0 ? std::string("post: {dialects: [linuxcnc], setup: auto}") : line) + "\n";
  }
  test::write_text(dir.file("job.yaml"), job);
  const test::RunResult r = test::run_flankcam("run " + dir.file("job.yaml") + " --quiet --out " + dir.file("out"), dir);
  INFO(job, r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& setup = report["setup"];
  REQUIRE(setup.is_object());
  CHECK(setup["unrotated"]["reachable"] == false);
  const double a = setup["chosen"]["rotate_deg"][0];
  MESSAGE("chosen rotate ", setup["chosen"]["rotate_deg"].dump(), ", ", setup["reason"].get<std::string>());
  CHECK(std::abs(a) >= 150);  // turned over (180, or 180 tilted by 15 or 30)
  CHECK(int(setup["chosen"]["singular_stretches"]) == 0);
  CHECK(fs::is_regular_file(dir.file("out/cone-1.ngc")));
}

TEST_CASE("post.setup: auto turns the conical-tool blade off the A = 0 singularity of xyzac-trt" * doctest::test_suite("heavy")) {
  // Unrotated, cone-1's tool axis stays within a few degrees of the C axis: C swings ~90 deg while
  // the axis turns ~3 deg (a near-singular stretch). auto must choose a rotation without one.
  test::ScratchDir dir("setup-auto");
  const std::string blade = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj";
  std::string job = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/examples/conical-tool/job.yaml");
  const size_t s = job.find("surface: ../blade/blade.obj");
  REQUIRE(s != std::string::npos);
  job.replace(s, std::string("surface: ../blade/blade.obj").size(), "surface: " + blade);
  const size_t p = job.find("post: {dialects: [linuxcnc]}");
  REQUIRE(p != std::string::npos);
  job.replace(p, std::string("post: {dialects: [linuxcnc]}").size(), "post: {dialects: [linuxcnc], setup: auto}");
  test::write_text(dir.file("job.yaml"), job);
  const pipeline::Job parsed = pipeline::read_job(dir.file("job.yaml"));
  CHECK(parsed.post.setup_auto);
  const test::RunResult r = test::run_flankcam("run " + dir.file("job.yaml") + " --quiet --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& setup = report["setup"];
  REQUIRE(setup.is_object());
  CHECK(int(setup["unrotated"]["singular_stretches"]) > 0);
  CHECK(double(setup["unrotated"]["max_rotary_deg_per_axis_deg"]) > 20);
  CHECK(int(setup["chosen"]["singular_stretches"]) == 0);
  CHECK(double(setup["chosen"]["min_singular_angle_deg"]) >= 10);
  CHECK(setup["chosen"]["rotate_deg"] != nlohmann::json::array({0, 0, 0}));
  CHECK(std::string(setup["reason"]).find("post.setup auto: rotate") == 0);
  // Every program runs with the chosen setup and has no near-singular stretch.
  int programs = 0;
  for (const auto& patch : report["patches"])
    for (const auto& prog : patch["programs"]) {
      ++programs;
      CHECK(prog["near_singular_stretches"].empty());
    }
  CHECK(programs == 3);
  const std::string cone1 = test::read_text(dir.file("out/cone-1.ngc"));
  const auto& rot = setup["chosen"]["rotate_deg"];
  CHECK(cone1.find(fmt::format("work frame = part rotated X {} Y {} Z {} deg", double(rot[0]), double(rot[1]),
                               double(rot[2]))) != std::string::npos);
  // verify places the part with the chosen rotation (from the program's header): clean.
  const test::RunResult v = test::run_flankcam("verify --job " + dir.file("job.yaml") + " " + dir.file("out/cone-1.ngc") +
                                                   " --out " + dir.file("v"),
                                               dir);
  INFO(v.err);
  CHECK(v.code == 0);
}
