#include <doctest/doctest.h>

#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include "core/closest_point.h"
#include "postproc/apt.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// An exact cone envelope (s-curve motion) from `flankcam envelope`, and its truth.
struct Generated {
  std::string mesh;
  nlohmann::json truth;
};
Generated generate(const test::ScratchDir& dir) {
  REQUIRE(test::run_flankcam("envelope --profile cone --motion s-curve --grid-s 40 --grid-t 140 --out " + dir.file("env"), dir)
              .code == 0);
  return {dir.file("env/envelope.obj"), nlohmann::json::parse(test::read_text(dir.file("env/truth.json")))};
}

// The true axis at row i of truth.json, moved by `off` mm (both ends) as a YAML list.
std::string line_at(const nlohmann::json& truth, size_t i, const Eigen::Vector3d& off) {
  const auto& r = truth["axis"][i];
  return fmt::format("[{}, {}, {}, {}, {}, {}]", double(r[0]) + off.x(), double(r[1]) + off.y(), double(r[2]) + off.z(),
                     double(r[3]) + off.x(), double(r[4]) + off.y(), double(r[5]) + off.z());
}

std::string job_text(const Generated& g) {
  const size_t n = g.truth["axis"].size();
  return fmt::format(R"(# exact cone envelope, two patches
surface: {}
# 0.05 mm: the test mesh (40 x 140) is coarse, its facets cut up to 0.03 mm into the exact tool (gouge check)
tool: {{shape: cone}}
tolerance: 0.05
sampling: {{s: 20, t: 80}}
patches:
  - name: surface-driven
    init: lines
    lines: [{}, {}, {}, {}, {}]
  - name: line-driven
    init: line
    line: {}
)",
                     g.mesh, line_at(g.truth, 0, {0.6, -0.4, 0.3}), line_at(g.truth, n / 4, {-0.5, 0.5, 0}),
                     line_at(g.truth, n / 2, {0.4, 0.3, -0.5}), line_at(g.truth, 3 * n / 4, {-0.3, -0.6, 0.2}),
                     line_at(g.truth, n - 1, {0.5, 0.2, 0.4}), line_at(g.truth, n / 2, {0.5, -0.5, 0.3}));
}
}  // namespace

TEST_CASE("flankcam fit: report in mm whose axis lies at the reported radii from the surface" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cli-fit");
  const Generated g = generate(dir);
  test::write_text(dir.file("job.yaml"), job_text(g));
  const test::RunResult run = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
  REQUIRE_MESSAGE(run.code == 0, run.err);
  CHECK(run.err.find("iteration 1,") != std::string::npos);  // progress on stderr
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const double diagonal = report["surface"]["diagonal_mm"];
  const SurfaceIndex surface(load_mesh(g.mesh).mesh);
  REQUIRE(report["patches"].size() == 2);
  for (const auto& p : report["patches"]) {
    const std::string name = p["name"];
    CAPTURE(name);
    const double eps = p["eps_opt"], eps_mm = p["eps_opt_mm"];
    MESSAGE(name << ": eps " << eps << " (" << eps_mm << " mm), coverage " << double(p["coverage"]));
    CHECK(eps <= 1e-4);
    CHECK(double(p["eps_ini"]) > eps);
    CHECK(eps_mm == doctest::Approx(eps * diagonal).epsilon(1e-3));
    REQUIRE(p["axis"].size() == 80);
    REQUIRE(p["radius"].size() == 20);
    CHECK(double(p["coverage"]) > 0.5);
    CHECK(double(p["coverage"]) <= 1.0);
    // ε re-measured from the report alone: axis rows at t_i, radii at s_j = j / (n - 1).
    double worst = 0;
    const double L = p["tool"]["length"];
    for (size_t i = 4; i + 4 < p["axis"].size(); i += 3) {
      const auto& r = p["axis"][i];
      const Eigen::Vector3d a(r[0], r[1], r[2]), b(r[3], r[4], r[5]);
      CHECK((b - a).norm() == doctest::Approx(L).epsilon(2e-3));
      for (size_t j = 2; j + 2 < p["radius"].size(); ++j) {
        const double s = double(j) / 19.0;
        const Footpoint f = surface.closest((1 - s) * a + s * b);
        if (!f.on_boundary) worst = std::max(worst, std::abs(f.distance - double(p["radius"][j])));
      }
    }
    CHECK(worst <= eps_mm + 1e-6);
    // The profile is the tool of the radii: a cone's meridian is a line from r(0) towards r(L).
    const auto& profile = p["tool"]["profile"];
    REQUIRE(profile.size() > 10);
    CHECK(std::string(p["tool"]["shape"]) == "cone");
    // Spheres of radius d(z) = d0 + k z envelope a cone of half angle asin(k). The tool is their
    // union between its end planes z = 0 and L: widest at z = L, where the last sphere (centre on
    // that plane, radius d1) is the widest of all (d(s)^2 - (L - sL)^2 grows with s for k < 1).
    const double d0 = p["radius"][0], d1 = p["radius"][19], k = (d1 - d0) / L;
    CHECK(double(p["tool"]["diameter_max"]) == doctest::Approx(2 * d1).epsilon(1e-5));
    CHECK(double(p["tool"]["cone_half_angle_deg"]) == doctest::Approx(std::asin(k) * 180 / M_PI).epsilon(1e-5));
    for (const std::string f : p["files"]) CHECK(std::filesystem::file_size(dir.file("out/" + f)) > 100);
    const std::string csv = test::read_text(dir.file("out/" + name + "-tool.csv"));
    CHECK(csv.find("z_mm,r_mm\n") != std::string::npos);
    const std::string ply = test::read_text(dir.file("out/" + name + "-deviation.ply"));
    CHECK(ply.find(fmt::format("element vertex {}\n", surface.mesh().vertices.size())) != std::string::npos);
    CHECK(ply.find("property double deviation_mm") != std::string::npos);
  }
  // The CL-data is the fitted motion: between approach and retract, one GOTO per axis row (tip a, unit axis).
  for (const auto& p : report["patches"]) {
    const std::string name = p["name"];
    const ClProgram cl = read_apt(dir.file("out/" + name + ".apt"));
    REQUIRE(cl.moves.size() == p["axis"].size() + 4);
    for (size_t i = 0; i < p["axis"].size(); ++i) {
      const auto& r = p["axis"][i];
      const Eigen::Vector3d a(r[0], r[1], r[2]), b(r[3], r[4], r[5]);
      const ClMove& m = cl.moves[i + 2];
      CHECK_FALSE(m.rapid);
      CHECK((m.pose.tip - a).norm() < 2e-6);
      CHECK((m.pose.axis - (b - a).normalized()).norm() < 1e-6);
    }
  }
  // The recovered cone matches the generator's (6 -> 9 mm) where the envelope pins it down.
  const auto& sd = report["patches"][0]["radius"];
  CHECK(double(sd[10]) == doctest::Approx(double(g.truth["radius"][20])).epsilon(0.15));
}

TEST_CASE("flankcam fit is deterministic: every file but the timings is byte-identical" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cli-fit-det");
  const Generated g = generate(dir);
  std::string job = job_text(g);
  job = job.substr(0, job.find("  - name: line-driven"));  // one patch is enough here
  test::write_text(dir.file("job.yaml"), job);
  for (const char* out : {"one", "two"})
    REQUIRE(test::run_flankcam("fit " + dir.file("job.yaml") + " --quiet --out " + dir.file(out), dir).code == 0);
  for (const char* f : {"surface-driven-envelope.ply", "surface-driven-deviation.ply", "surface-driven-tool.csv"}) {
    CAPTURE(f);
    CHECK(test::read_text(dir.file(std::string("one/") + f)) == test::read_text(dir.file(std::string("two/") + f)));
  }
  auto r1 = nlohmann::json::parse(test::read_text(dir.file("one/report.json")));
  auto r2 = nlohmann::json::parse(test::read_text(dir.file("two/report.json")));
  r1["patches"][0].erase("seconds");
  r2["patches"][0].erase("seconds");
  CHECK(r1.dump() == r2.dump());
}

TEST_CASE("flankcam fit: job errors name the key and line, exit 2 and write nothing") {
  test::ScratchDir dir("cli-fit-bad");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n");
  const std::string head = "surface: s.obj\n";
  const std::string patch = "patches:\n  - name: p\n    init: line\n    line: [0, 0, 1, 0, 0, 9]\n";
  struct Bad {
    const char* what;
    std::string text, expect;
  };
  const std::vector<Bad> cases = {
      {"unknown key", head + "tool: {shape: cone, lenght: 3}\n" + patch, "job.yaml:2: tool.lenght: unknown key"},
      {"unknown shape", head + "tool: {shape: ball}\n" + patch, "job.yaml:2: tool.shape: unknown shape 'ball'"},
      {"wrong type", head + "tolerance: fine\n" + patch, "job.yaml:2: tolerance: expected a number, got 'fine'"},
      {"negative", head + "tolerance: -1\n" + patch, "job.yaml:2: tolerance: must be in 1e-05 .. 100 mm, got -1"},
      {"nan", head + "patches:\n  - name: p\n    init: line\n    line: [0, 0, .nan, 0, 0, 9]\n",
       "job.yaml:5: patches[0].line[2]: must be finite"},
      {"five numbers", head + "patches:\n  - name: p\n    init: line\n    line: [0, 0, 0, 0, 9]\n",
       "job.yaml:5: patches[0].line: expected 6 numbers"},
      {"missing surface", "surface: nowhere.obj\n" + patch, "job.yaml:1: surface: file not found"},
      {"no patches", head, "patches: missing"},
      {"bad init", head + "patches:\n  - name: p\n    init: spiral\n", "job.yaml:4: patches[0].init: unknown initialisation"},
      {"duplicate name", head + patch + "  - name: p\n    init: line\n    line: [0, 0, 1, 0, 0, 9]\n",
       "job.yaml:6: patches[1].name: duplicate patch name 'p'"},
      {"unsafe name", head + "patches:\n  - name: ../x\n    init: line\n    line: [0, 0, 1, 0, 0, 9]\n",
       "patches[0].name: use letters"},
      {"sampling", head + "sampling: {s: 2}\n" + patch, "job.yaml:2: sampling.s: expected a whole number in 4..200"},
      {"yaml syntax", head + "tool: {shape: cone\n" + patch, "job.yaml:"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.what);
    test::write_text(dir.file("job.yaml"), c.text);
    const test::RunResult r = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
    CAPTURE(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find(c.expect) != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);  // one line
    CHECK_FALSE(std::filesystem::exists(dir.file("out/report.json")));
  }
  CHECK(test::run_flankcam("fit " + dir.file("absent.yaml") + " --out " + dir.file("out"), dir).code == 2);
}

TEST_CASE("flankcam fit checks shank and holder against the part: a shank wider than the tool is reported" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cli-fit-collide");
  const Generated g = generate(dir);
  std::string job = job_text(g);
  job = job.substr(0, job.find("  - name: line-driven"));
  for (const std::string shank : {"8", "30"}) {
    CAPTURE(shank);
    std::string with = job;
    with.insert(with.find("tolerance:"), "holder: {shank_length: 20, shank_diameter: " + shank +
                                             ", length: 30, diameter: 32, diameter_far: 50}\nclearance: 0.5\n");
    test::write_text(dir.file("job.yaml"), with);
    const std::string out = dir.file("out" + shank);
    const test::RunResult run = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + out, dir);
    // A collision still writes the report (to look at) but fails the run unless allowed.
    REQUIRE_MESSAGE(run.code == (shank == "8" ? 0 : 4), run.err);
    if (shank == "30") {
      CHECK(run.err.find("flankcam: patch surface-driven collides: shank") != std::string::npos);
      const test::RunResult allowed =
          test::run_flankcam("fit " + dir.file("job.yaml") + " --allow-collisions --quiet --out " + out + "-allowed", dir);
      CHECK(allowed.code == 0);
      CHECK_FALSE(std::filesystem::exists(out + "/surface-driven.apt"));  // no program for a colliding motion ...
      CHECK(test::read_text(out + "-allowed/surface-driven.apt").find("WARNING: COLLISIONS ALLOWED") != std::string::npos);
      CHECK(allowed.err.find("flankcam: patch surface-driven (allowed) collides: shank") != std::string::npos);
    }
    const nlohmann::json report = nlohmann::json::parse(test::read_text(out + "/report.json"));
    const auto& col = report["patches"][0]["collisions"];
    if (shank == "8") {
      CHECK_MESSAGE(col.empty(), run.err);  // Ø8 stays inside the cone's 6-9 mm radii: clear, and no gouge on the exact envelope
      CHECK_FALSE(std::filesystem::exists(out + "/surface-driven-collisions.obj"));
    } else {
      REQUIRE(!col.empty());
      CHECK(std::string(col[0]["component"]) == "shank");
      // The shank's end face (r = 15) sits 0.1 mm above the envelope's top edge: within the 0.5 mm clearance.
      CHECK(double(col[0]["depth_mm"]) > -0.5);
      CHECK(run.err.find("patch surface-driven: shank inside the clearance at poses") != std::string::npos);
      CHECK(std::filesystem::file_size(out + "/surface-driven-collisions.obj") > 1000);
    }
  }
}

namespace {
// OBJ text of a mesh (1-based faces).
std::string obj_text(const flankcam::TriMesh& m) {
  std::string s;
  for (const Eigen::Vector3d& v : m.vertices) s += fmt::format("v {} {} {}\n", v.x(), v.y(), v.z());
  for (const auto& f : m.faces) s += fmt::format("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
  return s;
}
}  // namespace

namespace {
// One patch along the flank x = 0 of the tests below: upright axis lines 5 mm off it, y 5..50.
const std::string kFlankPatch =
    "patches:\n  - name: flank\n    init: lines\n    lines:\n"
    "      - [5, 5, 0, 5, 5, 20]\n      - [5, 20, 0, 5, 20, 20]\n      - [5, 35, 0, 5, 35, 20]\n      - [5, 50, 0, 5, 50, 20]\n";
}  // namespace

TEST_CASE("flankcam fit with a part: the part's twin of the flank is left to the flank, and a post in the way trims the motion" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cli-fit-check");
  // The flank x = 0 (y 0..60, z 0..20 mm, normals +x); the part: the blade behind it, whose flank
  // side is the flank's twin, and a post at y >= 52 standing where the tool (Ø10 about x = 5) would
  // end its motion.
  const flankcam::TriMesh flank = test::grid_mesh(31, 11, [](int j, int k) { return Eigen::Vector3d(0, 2.0 * j, 2.0 * k); });
  test::write_text(dir.file("flank.obj"), obj_text(flank));
  flankcam::TriMesh part = test::box_mesh({-10, 0, 0}, {0, 60, 20});
  const flankcam::TriMesh post = test::box_mesh({1, 52, -10}, {30, 80, 100});
  const int n = int(part.vertices.size());
  part.vertices.insert(part.vertices.end(), post.vertices.begin(), post.vertices.end());
  for (auto f : post.faces) part.faces.push_back({f[0] + n, f[1] + n, f[2] + n});
  test::write_text(dir.file("part.obj"), obj_text(part));
  const std::string job =
      "surface: flank.obj\n"
      "part: part.obj\n"
      "check_tolerance: 0.001\n"
      "tool: {shape: general}\n"
      "tolerance: 0.005\n" +
      kFlankPatch;
  test::write_text(dir.file("job.yaml"), job);
  const test::RunResult run = test::run_flankcam("fit " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
  // The twin is left out (the flank is judged with the fitted tolerance); the post is kept clear of.
  REQUIRE_MESSAGE(run.code == 0, run.err);
  CHECK(run.err.find("24 triangles, 2 of them the design surface's twin") != std::string::npos);
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& p = report["patches"][0];
  CHECK(p["collisions"].empty());
  const auto& c = p["check_surface"];
  CHECK(double(c["worst_intrusion_mm"]) <= 0.0);
  CHECK(int(c["twin_triangles_left_to_the_surface"]) == 2);
  CHECK(double(c["check_tolerance_mm"]) == 0.001);
  CHECK_FALSE(bool(c["refused"]));
  CHECK(double(p["eps_opt_mm"]) < 0.005);
  CHECK(double(p["coverage"]) > 0.6);  // the flank up to the post, less the tool's radius
  // The motion stops short of the post: the last CL point's tool (radius 5) ends before y = 52.
  const std::string apt = test::read_text(dir.file("out/flank.apt"));
  CHECK(apt.find("GOTO") != std::string::npos);
  // check_tolerance needs a part.
  std::string no_part = job;
  no_part.erase(no_part.find("part: part.obj\n"), 15);
  test::write_text(dir.file("bad.yaml"), no_part);
  const test::RunResult bad = test::run_flankcam("fit " + dir.file("bad.yaml") + " --out " + dir.file("bad"), dir);
  CHECK(bad.code == 2);
  CHECK(bad.err.find("bad.yaml:2: check_tolerance: needs part:") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir.file("bad")));
}

TEST_CASE("flankcam run with a part whose coarse twin of a dished flank stands 0.09 mm proud: the program is judged against the flank and the rest of the part, not the twin" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cli-run-twin");
  // The flank dished by 0.09 mm in its middle, x = -0.09 (1 - ((y - 30) / 30)^2) (y 0..60, z 0..20);
  // the part: the blade block behind it, whose flank side is one coarse quad through the flank's
  // corners, so it stands up to 0.09 mm proud of the flank. The tool cuts the flank; against the
  // block it would be a 0.09 mm "gouge", far beyond the 0.005 mm tolerance.
  const flankcam::TriMesh flank = test::grid_mesh(31, 11, [](int j, int k) {
    const double y = 2.0 * j, u = (y - 30) / 30;
    return Eigen::Vector3d(-0.09 * (1 - u * u), y, 2.0 * k);
  });
  test::write_text(dir.file("flank.obj"), obj_text(flank));
  test::write_text(dir.file("part.obj"), obj_text(test::box_mesh({-10, 0, 0}, {0, 60, 20})));
  const std::string job =
      "surface: flank.obj\n"
      "part: part.obj\n"
      "holder: {shank_length: 10, shank_diameter: 6, length: 20, diameter: 16, diameter_far: 16}\n"
      "tool: {shape: cylinder}\n"
      "tolerance: 0.005\n"
      "machine: xyzac-trt\n"
      "post: {dialects: [linuxcnc]}\n" +
      kFlankPatch;
  test::write_text(dir.file("job.yaml"), job);
  const test::RunResult run = test::run_flankcam("run " + dir.file("job.yaml") + " --out " + dir.file("out"), dir);
  REQUIRE_MESSAGE(run.code == 0, run.err);
  CHECK(run.err.find("2 of them the design surface's twin (left to the surface itself, up to 0.090 mm off it)") != std::string::npos);
  CHECK(std::filesystem::exists(dir.file("out/flank.ngc")));
  // What the back-simulation of the written program says: the flank within 0.005 mm where it is cut.
  const nlohmann::json report = nlohmann::json::parse(test::read_text(dir.file("out/report.json")));
  const auto& p = report["patches"][0];
  CHECK(p["collisions"].empty());
  CHECK(double(p["eps_opt_mm"]) < 0.005);
  CHECK(double(p["coverage"]) > 0.6);
}
