// `flankcam verify` through the real program: the run's own program is clean, a program with one
// cutting block moved 1 mm into the blade is refused naming that line, a bad --out writes nothing.
#include <doctest/doctest.h>

#include <fmt/format.h>
#include <sys/wait.h>

#include <Eigen/Core>

#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "core/closest_point.h"
#include "postproc/apt.h"
#include "tests/test_util.h"

using namespace flankcam;
namespace fs = std::filesystem;

namespace {

struct Output {
  int code = -1;
  std::string out, err;
};

// Runs flankcam with `args`, keeping stdout and stderr.
Output run_program(const std::string& args, const test::ScratchDir& dir) {
  const std::string out = dir.file("stdout.txt"), err = dir.file("stderr.txt");
  const int status = std::system((std::string(FLANKCAM_BINARY) + " " + args + " > " + out + " 2> " + err).c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, test::read_text(out), test::read_text(err)};
}

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

// `lines` with the given coordinate of line `index` (0-based) moved by `delta_mm`.
std::string moved(std::vector<std::string> lines, size_t index, char axis, double delta_mm) {
  const std::regex word(std::string(1, axis) + R"((-?[0-9]+\.?[0-9]*))");
  std::smatch m;
  REQUIRE(std::regex_search(lines[index], m, word));
  lines[index] = m.prefix().str() + fmt::format("{}{:.4f}", axis, std::stod(m[1].str()) + delta_mm) + m.suffix().str();
  std::string text;
  for (const std::string& l : lines) text += l + "\n";
  return text;
}

// `flankcam run JOB --out DIR/run` (it must succeed); the run's folder.
std::string run_job(const std::string& job, const test::ScratchDir& dir) {
  const std::string run = dir.file("run");
  const Output r = run_program("run " + job + " --quiet --out " + run, dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  return run;
}

}  // namespace

TEST_CASE("flankcam verify: the conical-tool run is clean, a block moved 1 mm into the blade is refused naming its line" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("verify");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/conical-tool/job.yaml";
  const std::string run = run_job(job, dir);
  const std::string program = (fs::path(run) / "cone-1.ngc").string();

  // The cutter verify reads beside the program (cone-1-tool.csv, also the APT profile and the DXF)
  // is the cutter the run checked and back-simulated: the union of the fitted spheres d(s),
  // s in [0, 1], centred on the axis at sL, between the end planes z = 0 and z = L. For the cone
  // d(s) = d0 + (d1 - d0) s it is computed here from report.json's radii alone. (Before, the file held
  // the spheres' envelope, the cone d cos(half angle) ending d1 sin(half angle) below L, which is not
  // what the run checked: verify refused a program the run had written clean.)
  {
    const auto report = nlohmann::json::parse(test::read_text(run + "/report.json"));
    const auto& patch = report["patches"][0];
    const double d0 = patch["radius"][0], d1 = patch["radius"][patch["radius"].size() - 1];
    const double L = patch["tool"]["length"];
    std::vector<Eigen::Vector2d> csv;
    for (const std::string& l : split_lines(test::read_text(run + "/cone-1-tool.csv")))
      if (!l.empty() && (std::isdigit(static_cast<unsigned char>(l[0])) || l[0] == '-'))
        csv.emplace_back(std::stod(l), std::stod(l.substr(l.find(',') + 1)));
    REQUIRE(csv.size() > 20);
    CHECK(csv.front().x() == doctest::Approx(0).scale(1).epsilon(1e-4));
    CHECK(csv.back().x() == doctest::Approx(L).epsilon(1e-5));
    double worst = 0;
    for (const Eigen::Vector2d& zr : csv) {
      double r2 = 0;
      for (int k = 0; k <= 20000; ++k) {
        const double s = k / 20000.0, d = d0 + (d1 - d0) * s, dz = zr.x() - s * L;
        r2 = std::max(r2, d * d - dz * dz);
      }
      worst = std::max(worst, std::abs(zr.y() - std::sqrt(r2)));
    }
    MESSAGE("tool file vs the spheres' union: " << worst << " mm over " << csv.size() << " points");
    CHECK(worst < 2e-4);
  }

  SUBCASE("the posted program is clean") {
    const Output r = run_program("verify --job " + job + " " + program + " --out " + dir.file("v"), dir);
    INFO(r.out, r.err);
    CHECK(r.code == 0);
    REQUIRE(fs::is_regular_file(dir.file("v/verify.json")));
    CHECK(fs::is_regular_file(dir.file("v/verify.html")));
    const auto report = nlohmann::json::parse(test::read_text(dir.file("v/verify.json")));
    REQUIRE(report["programs"].size() == 1);
    const auto& p = report["programs"][0];
    CHECK(p["clean"] == true);
    CHECK(p["collisions_and_gouges"].empty());
    CHECK(int(p["motion_blocks"]) > 50);
    // Rapids keep the job's clearance (1 mm); the cutter reaches most of the patch's side.
    CHECK(double(p["min_clearance_rapid_mm"]["cutter"]) >= 0.9);
    CHECK(double(p["design_surface"]["coverage"]) > 0.5);
    CHECK(r.out.find("cone-1.ngc: clean") != std::string::npos);
  }

  SUBCASE("rapids are judged against the job's clearance: inside it a finding with its line and distance, exit 4") {
    // The same program verified with jobs that differ from the run's only in `clearance`: just below
    // the program's closest rapid it is clean, above it that rapid is a clearance finding.
    const Output r0 = run_program("verify --job " + job + " " + program + " --out " + dir.file("v0"), dir);
    REQUIRE(r0.code == 0);
    const auto clean = nlohmann::json::parse(test::read_text(dir.file("v0/verify.json")));
    CHECK(double(clean["rapid_clearance_mm"]) == 1);  // the job's
    double closest = INFINITY;
    for (const char* part : {"cutter", "shank", "holder"})
      closest = std::min(closest, double(clean["programs"][0]["min_clearance_rapid_mm"][part]));
    REQUIRE(closest >= 1);
    REQUIRE(closest < 20);
    const std::string source = test::read_text(job);
    const auto job_with = [&](double clearance, const std::string& name) {
      std::string text = source;
      const std::string surface = "surface: ../blade/blade.obj", given = "clearance: 1\n";
      REQUIRE(text.find(surface) != std::string::npos);
      REQUIRE(text.find(given) != std::string::npos);
      text.replace(text.find(surface), surface.size(),
                   "surface: " + std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj");
      text.replace(text.find(given), given.size(), fmt::format("clearance: {}\n", clearance));
      const std::string path = dir.file(name);
      test::write_text(path, text);
      return path;
    };
    const Output below =
        run_program("verify --job " + job_with(closest - 0.05, "below.yaml") + " " + program + " --out " + dir.file("vb"), dir);
    INFO(below.out, below.err);
    CHECK(below.code == 0);
    const double wide = closest + 0.5;
    const Output above =
        run_program("verify --job " + job_with(wide, "above.yaml") + " " + program + " --out " + dir.file("va"), dir);
    INFO(above.out, above.err);
    CHECK(above.code == 4);
    CHECK(above.out.find(fmt::format("inside the rapid clearance of {} mm", wide)) != std::string::npos);
    const auto report = nlohmann::json::parse(test::read_text(dir.file("va/verify.json")));
    const auto& p = report["programs"][0];
    CHECK(p["clean"] == false);
    double nearest = INFINITY;
    for (const auto& h : p["collisions_and_gouges"]) {
      CHECK(h["motion"] != "feed");
      CHECK(h["kind"] == "clearance");
      CHECK(double(h["depth_mm"]) <= 0);
      CHECK(-double(h["depth_mm"]) < wide);
      nearest = std::min(nearest, -double(h["depth_mm"]));
    }
    CHECK(nearest == doctest::Approx(closest).epsilon(1e-3));
  }

  SUBCASE("one cutting block moved 1 mm sideways into the blade: exit 4 naming that line") {
    // A modal feed block well inside the cut: 20 lines after the first G1.
    const std::vector<std::string> lines = split_lines(test::read_text(program));
    size_t g1 = 0;
    while (g1 < lines.size() && lines[g1].find("G1 ") == std::string::npos) ++g1;
    REQUIRE(g1 + 20 < lines.size());
    const size_t index = g1 + 20;
    for (size_t k = g1; k <= index; ++k) REQUIRE(lines[k].find("G0") == std::string::npos);
    REQUIRE(lines[index].find('Z') != std::string::npos);
    const int line = int(index) + 1;
    // On the table-table machine the tool stands along machine Z; 1 mm along machine X moves the
    // cutter into the blade on one side and away from it on the other: the sweep sees the one, the
    // comparison with cone-1.apt (beside the program) both.
    int refused = 0, gouging = 0;
    for (const double delta : {-1.0, 1.0}) {
      CAPTURE(delta);
      const fs::path bad = fs::path(run) / "bad-1.ngc";  // beside cone-1-tool.csv under another name
      test::write_text(bad.string(), moved(lines, index, 'X', delta));
      fs::copy_file(fs::path(run) / "cone-1-tool.csv", fs::path(run) / "bad-1-tool.csv", fs::copy_options::overwrite_existing);
      const std::string out = dir.file(fmt::format("bad{}", delta > 0 ? "+" : "-"));
      const Output r = run_program("verify --job " + job + " " + bad.string() + " --out " + out, dir);
      INFO(r.out, r.err);
      REQUIRE((r.code == 0 || r.code == 4));
      REQUIRE(fs::is_regular_file(out + "/verify.json"));  // written either way
      if (r.code == 0) continue;
      ++refused;
      CHECK(r.out.find(fmt::format("bad-1.ngc:{}:", line)) != std::string::npos);
      CHECK(r.err.find("1 of 1 program(s) collide or gouge") != std::string::npos);
      const auto report = nlohmann::json::parse(test::read_text(out + "/verify.json"));
      const auto& p = report["programs"][0];
      CHECK(p["clean"] == false);
      gouging += !p["collisions_and_gouges"].empty();
      bool at_line = false;
      for (const auto& h : p["collisions_and_gouges"]) {
        at_line |= int(h["line"]) == line;
        CHECK(double(h["depth_mm"]) > 0.01);  // beyond the tolerance
        CHECK(double(h["depth_mm"]) < 1.1);   // no deeper than the move
      }
      for (const auto& d : p["cl_data"]["off_cl_data"]) {
        at_line |= int(d["line"]) == line;
        // The tip's distance from the CL polyline: at most the 1 mm it moved.
        CHECK(double(d["deviation_mm"]) > 0.1);
        CHECK(double(d["deviation_mm"]) < 1.01);
      }
      CHECK(at_line);
    }
    CHECK(refused == 2);
    CHECK(gouging == 1);
  }

  SUBCASE("one cutting block's Z lowered by 1 mm: exit 4 naming that line; without the CL-data it is said") {
    const std::vector<std::string> lines = split_lines(test::read_text(program));
    size_t g1 = 0;
    while (g1 < lines.size() && lines[g1].find("G1 ") == std::string::npos) ++g1;
    const size_t index = g1 + 40;
    REQUIRE(index < lines.size());
    REQUIRE(lines[index].find('Z') != std::string::npos);
    const fs::path bad = fs::path(run) / "lowered.ngc";
    test::write_text(bad.string(), moved(lines, index, 'Z', -1.0));
    const Output r = run_program("verify --job " + job + " " + bad.string() + " --out " + dir.file("low"), dir);
    INFO(r.out, r.err);
    CHECK(r.code == 4);
    CHECK(r.out.find(fmt::format("lowered.ngc:{}:", index + 1)) != std::string::npos);
    const auto report = nlohmann::json::parse(test::read_text(dir.file("low/verify.json")));
    const auto& cl = report["programs"][0]["cl_data"];
    REQUIRE(cl["files"].size() == 1);
    CHECK(std::string(cl["files"][0]).find("cone-1.apt") != std::string::npos);
    CHECK(int(cl["feed_blocks_compared"]) > 50);

    // The program and its tool alone in another folder: checked geometrically, and said so.
    const fs::path alone = fs::path(dir.file("alone"));
    fs::create_directories(alone);
    fs::copy_file(program, alone / "cone-1.ngc");
    fs::copy_file(fs::path(run) / "cone-1-tool.csv", alone / "cone-1-tool.csv");
    const std::string copy = (alone / "cone-1.ngc").string();
    const Output plain = run_program("verify --job " + job + " " + copy + " --out " + dir.file("alone-v"), dir);
    INFO(plain.out, plain.err);
    CHECK(plain.code == 0);
    CHECK(plain.out.find("no cone-1.apt beside the program") != std::string::npos);
    const auto plain_report = nlohmann::json::parse(test::read_text(dir.file("alone-v/verify.json")));
    CHECK(plain_report["programs"][0]["cl_data"]["files"].empty());
    CHECK(std::string(plain_report["programs"][0]["cl_data"]["note"]).find("not compared") != std::string::npos);
    // --cl names it.
    const Output given = run_program("verify --job " + job + " " + copy + " --cl " + copy + "=" +
                                          (fs::path(run) / "cone-1.apt").string() + " --out " + dir.file("given-v"),
                                      dir);
    INFO(given.out, given.err);
    CHECK(given.code == 0);
    CHECK(given.out.find("cutting blocks on the CL-data") != std::string::npos);
    // --cl for a program not verified: exit 2.
    const Output wrong = run_program("verify --job " + job + " " + copy + " --cl other.ngc=x.apt --out " + dir.file("w"), dir);
    CHECK(wrong.code == 2);
    CHECK(wrong.err.find("--cl other.ngc=x.apt") != std::string::npos);
  }

  SUBCASE("--out naming an existing file: exit 2, nothing written") {
    const std::string file = dir.file("taken.txt");
    test::write_text(file, "keep me\n");
    size_t entries = 0;
    for (const auto& e : fs::directory_iterator(dir.path)) entries += e.path().filename() != "stdout.txt" && e.path().filename() != "stderr.txt";
    const Output r = run_program("verify --job " + job + " " + program + " --out " + file, dir);
    INFO(r.out, r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("--out") != std::string::npos);
    CHECK(r.out.empty());
    CHECK(test::read_text(file) == "keep me\n");
    size_t after = 0;
    for (const auto& e : fs::directory_iterator(dir.path)) after += e.path().filename() != "stdout.txt" && e.path().filename() != "stderr.txt";
    CHECK(after == entries);
    CHECK(!fs::exists(fs::path(run) / "verify.json"));
  }
}

TEST_CASE("flankcam verify: APT CL-data (part coordinates) is placed on the machine like the part" * doctest::test_suite("heavy")) {
  // The conical-tool job's first patch with the part turned and moved on the table: programs are in
  // the work frame, the APT stays in part coordinates. Verifying the APT must cut the blade as the
  // program does (before, its moves were judged in part coordinates against the placed part: the
  // tool never met the blade and the APT was "clean" with 0% of the surface reached).
  test::ScratchDir dir("verify-apt-setup");
  const std::string examples = std::string(FLANKCAM_SOURCE_DIR) + "/examples";
  std::string job = test::read_text(examples + "/conical-tool/job.yaml");
  const std::string surface = "surface: ../blade/blade.obj", post = "post: {dialects: [linuxcnc]}";
  REQUIRE(job.find(surface) != std::string::npos);
  REQUIRE(job.find(post) != std::string::npos);
  job.replace(job.find(surface), surface.size(), "surface: " + examples + "/blade/blade.obj");
  job.replace(job.find(post), post.size(), "post: {dialects: [linuxcnc], setup: {rotate: [0, 0, 90], translate: [20, -10, 30]}}");
  job = job.substr(0, job.find("  - name: cone-2"));  // one patch
  const std::string job_file = dir.file("job.yaml");
  test::write_text(job_file, job);
  const std::string run = run_job(job_file, dir);
  const auto verify = [&](const std::string& program, const std::string& out) {
    const Output r = run_program("verify --job " + job_file + " " + program + " --out " + dir.file(out), dir);
    INFO(r.out, r.err);
    CHECK(r.code == 0);
    return nlohmann::json::parse(test::read_text(dir.file(out + "/verify.json")))["programs"][0];
  };
  const auto ngc = verify(run + "/cone-1.ngc", "v-ngc"), apt = verify(run + "/cone-1.apt", "v-apt");
  MESSAGE("reached: ngc ", ngc["design_surface"]["vertices_reached"], ", apt ", apt["design_surface"]["vertices_reached"]);
  CHECK(apt["clean"] == true);
  CHECK(int(apt["design_surface"]["vertices_reached"]) > 100);
  CHECK(double(apt["design_surface"]["coverage"]) > 0.5);
  // The CL-data and the program cut the same surface.
  CHECK(double(apt["design_surface"]["coverage"]) == doctest::Approx(double(ngc["design_surface"]["coverage"])).epsilon(0.05));
}

TEST_CASE("flankcam run: each NAME.apt carries its program's links, verify finds it clean with the job's clearance in its rapids" * doctest::test_suite("heavy")) {
  // Before, the APT approached and left along the tool axis (a rapid to retract, a rapid to lead_in
  // above the first pose): on the conical-tool blade those rapids slid the cone along the flank it
  // touches, 0.04 and 0.06 mm into the blade for cone-2 and cone-3 and 0.003 mm off it for cone-1,
  // while the programs of the same patches, whose links are planned against the part, were clean.
  test::ScratchDir dir("verify-apt-links");
  const std::string job = std::string(FLANKCAM_SOURCE_DIR) + "/examples/conical-tool/job.yaml";
  const std::string run = run_job(job, dir);
  const double clearance = 1, retract = 50;  // the job's clearance, the default retract (mm)
  const std::vector<std::string> patches = {"cone-1", "cone-2", "cone-3"};
  std::string files;
  for (const std::string& name : patches) files += " " + run + "/" + name + ".apt " + run + "/" + name + ".ngc";
  {
    const Output r = run_program("verify --job " + job + files + " --out " + dir.file("v"), dir);
    INFO(r.out, r.err);
    CHECK(r.code == 0);
  }
  const auto report = nlohmann::json::parse(test::read_text(dir.file("v/verify.json")));
  REQUIRE(report["programs"].size() == 2 * patches.size());
  for (const auto& p : report["programs"]) {
    const std::string file = p["file"];
    CAPTURE(file);
    CHECK(p["clean"] == true);
    CHECK(p["collisions_and_gouges"].empty());
    for (const char* part : {"cutter", "shank", "holder"}) CHECK(double(p["min_clearance_rapid_mm"][part]) >= clearance - 0.1);
    CHECK(double(p["design_surface"]["coverage"]) > 0.5);
    if (file.find(".ngc") != std::string::npos) {  // the program on its APT, leads included
      CHECK(int(p["cl_data"]["feed_blocks_compared"]) > 50);
      CHECK(p["cl_data"]["off_cl_data"].empty());
    }
  }

  // Each APT enters and leaves as its program does: down the tool axis from `retract` above the lead
  // point, a feed in across the axis from off the surface onto the flank, the cut, a feed out across the
  // axis, a rapid `retract` up the axis.
  const SurfaceIndex blade(load_mesh(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj").mesh);
  for (const std::string& name : patches) {
    CAPTURE(name);
    const ClProgram cl = read_apt(run + "/" + name + ".apt");
    const size_t n = cl.moves.size();
    REQUIRE(n > 10);
    REQUIRE(cl.profile.size() >= 2);
    const double H = cl.profile.back().x();
    const auto axial_by = [](const ToolPose& from, const ToolPose& to) {  // `to` along from's axis, or NaN
      const Eigen::Vector3d d = to.tip - from.tip, a = from.axis.normalized();
      return (d - d.dot(a) * a).norm() < 1e-5 && (to.axis - from.axis).norm() < 1e-8 ? d.dot(a) : NAN;
    };
    CHECK(cl.moves[0].rapid);
    CHECK(cl.moves[1].rapid);
    CHECK(axial_by(cl.moves[1].pose, cl.moves[0].pose) == doctest::Approx(retract).epsilon(1e-6));
    CHECK(!cl.moves[2].rapid);
    CHECK(cl.moves[n - 1].rapid);
    CHECK(!cl.moves[n - 2].rapid);
    CHECK(axial_by(cl.moves[n - 2].pose, cl.moves[n - 1].pose) == doctest::Approx(retract).epsilon(1e-6));
    // The lead from the cut's end pose `on` to the lead point `off`: across the axis, at least the
    // clearance long, away from the surface (the side of the axis the flank is not on).
    const auto lead = [&](const ToolPose& on, const ToolPose& off, const std::string& which) {
      CAPTURE(which);
      const Eigen::Vector3d a = on.axis.normalized(), d = off.tip - on.tip, across = d - d.dot(a) * a;
      const Eigen::Vector3d mid = on.tip + 0.5 * H * a;
      Eigen::Vector3d out = mid - blade.closest(mid).point;  // from the flank to the axis
      out = (out - out.dot(a) * a).normalized();
      MESSAGE(name << " " << which << ": " << across.norm() << " mm across the axis, " << d.dot(a)
                   << " mm along it, cos to the surface normal " << across.normalized().dot(out));
      CHECK(across.norm() >= clearance);
      CHECK(std::abs(d.dot(a)) <= across.norm() + 1e-9);  // lifted by at most a whole lead
      CHECK(across.normalized().dot(out) > 0.5);
    };
    lead(cl.moves[2].pose, cl.moves[1].pose, "lead-in");
    lead(cl.moves[n - 3].pose, cl.moves[n - 2].pose, "lead-out");
  }
}
