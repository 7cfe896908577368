#include "postproc/viewer.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <random>

#include "core/errors.h"
#include "kinematics/machine.h"
#include "postproc/apt.h"
#include "postproc/verify_view.h"
#include "tests/postproc/wall.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

std::vector<std::uint8_t> unbase64(const std::string& s) {
  std::vector<std::uint8_t> out;
  unsigned buf = 0;
  int bits = 0;
  for (char c : s) {
    int v;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    else if (c >= '0' && c <= '9') v = c - '0' + 52;
    else if (c == '+') v = 62;
    else if (c == '/') v = 63;
    else continue;  // '=' padding
    buf = buf << 6 | unsigned(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(std::uint8_t(buf >> bits & 255));
    }
  }
  return out;
}
std::uint32_t u32_at(const std::vector<std::uint8_t>& b, size_t i) {
  return std::uint32_t(b[4 * i]) | std::uint32_t(b[4 * i + 1]) << 8 | std::uint32_t(b[4 * i + 2]) << 16 |
         std::uint32_t(b[4 * i + 3]) << 24;
}
std::vector<float> floats(const std::string& s) {
  const std::vector<std::uint8_t> b = unbase64(s);
  std::vector<float> f(b.size() / 4);
  for (size_t i = 0; i < f.size(); ++i) {
    const std::uint32_t v = u32_at(b, i);
    std::memcpy(&f[i], &v, 4);
  }
  return f;
}

// A scene with every kind of content: a wavy Φ, one patch (cone meridian, shank, holder, Ω, poses
// along the surface, a marker) and a track of its poses with programmed values.
ViewerScene small_scene(int nx = 12, int ny = 8) {
  ViewerScene s;
  s.tolerance_mm = 0.01;
  s.surface_mm = test::wavy_grid(nx, ny, 40, 30, 2);
  ViewerPatch p;
  p.name = "cone-1";
  for (int j = 0; j <= 10; ++j) p.meridian.emplace_back(3.0 * j, 2.0 + 0.05 * j);
  p.assembly.shank_length = 20, p.assembly.shank_diameter = 8;
  p.assembly.holder_length = 40, p.assembly.holder_diameter = 25, p.assembly.holder_diameter_far = 40;
  p.assembly.holder_cylinder_length = 10;
  std::mt19937 rng;
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  for (size_t i = 0; i < s.surface_mm.vertices.size(); ++i) p.design_deviation_mm.push_back(i % 7 == 0 ? std::nan("") : u(rng));
  p.envelope_mm = test::wavy_grid(6, 5, 40, 30, 2);
  for (int i = 0; i < 20; ++i) {
    const double a = 0.1 * i;
    p.poses.push_back({Eigen::Vector3d(2.0 * i, 1.5, -0.25 * i), Eigen::Vector3d(std::sin(a), 0, std::cos(a))});
  }
  p.markers.push_back({Eigen::Vector3d(10, 2, 3), 13, "holder collides at poses 12-14, 0.731 mm deep", {}});
  s.patches.push_back(p);
  ViewerTrack t;
  t.name = "cone-1.ngc";
  t.axis_names = {"X", "Y", "Z", "A", "C"};
  for (size_t i = 0; i < p.poses.size(); ++i)
    t.frames.push_back({p.poses[i], {1.0 * i, -2.0 * i, 3.5, 10.0 + i, -90.0 + 0.5 * i}, i < 2, 0, 0});
  s.tracks.push_back(t);
  return s;
}

}  // namespace

TEST_CASE("deviation_band: within the tolerance, overcut below it, undercut above it, none where undefined") {
  CHECK(deviation_band(0.0, 0.01) == DeviationBand::Within);
  CHECK(deviation_band(0.01, 0.01) == DeviationBand::Within);
  CHECK(deviation_band(-0.01, 0.01) == DeviationBand::Within);
  CHECK(deviation_band(0.0101, 0.01) == DeviationBand::Under);
  CHECK(deviation_band(-0.0101, 0.01) == DeviationBand::Over);
  CHECK(deviation_band(std::nan(""), 0.01) == DeviationBand::None);
  CHECK(deviation_band(INFINITY, 0.01) == DeviationBand::None);
}

TEST_CASE("viewer_json: poses, programmed values, meridians, mesh and bands decode to the scene's numbers") {
  const ViewerScene s = small_scene();
  const nlohmann::json j = nlohmann::json::parse(viewer_json(s));
  CHECK(j["units"] == "mm");
  CHECK(j["tolerance_mm"].get<double>() == doctest::Approx(0.01));

  // Φ, undecimated at this size: positions and triangles as given.
  const auto& surf = j["surface"];
  REQUIRE(surf["vertices"].get<size_t>() == s.surface_mm.vertices.size());
  REQUIRE(surf["triangles"].get<size_t>() == s.surface_mm.faces.size());
  const std::vector<float> pos = floats(surf["positions"]);
  REQUIRE(pos.size() == 3 * s.surface_mm.vertices.size());
  for (size_t i = 0; i < s.surface_mm.vertices.size(); ++i)
    for (int c = 0; c < 3; ++c) CHECK(pos[3 * i + c] == doctest::Approx(s.surface_mm.vertices[i][c]).epsilon(1e-6));
  const std::vector<std::uint8_t> idx = unbase64(surf["indices"]);
  REQUIRE(idx.size() == 12 * s.surface_mm.faces.size());
  for (size_t f = 0; f < s.surface_mm.faces.size(); ++f)
    for (int c = 0; c < 3; ++c) CHECK(u32_at(idx, 3 * f + c) == std::uint32_t(s.surface_mm.faces[f][c]));

  const ViewerPatch& p = s.patches[0];
  const auto& jp = j["patches"][0];
  CHECK(jp["name"] == "cone-1");
  // Bands: one per vertex, the patch's and (one patch) the combined ones equal.
  const std::vector<std::uint8_t> bands = unbase64(jp["bands"]);
  REQUIRE(bands.size() == s.surface_mm.vertices.size());
  int counts[4] = {0, 0, 0, 0};
  for (size_t i = 0; i < bands.size(); ++i) {
    CHECK(bands[i] == std::uint8_t(deviation_band(p.design_deviation_mm[i], s.tolerance_mm)));
    ++counts[bands[i]];
  }
  CHECK(unbase64(j["bands"]) == bands);
  for (int b = 0; b < 4; ++b) CHECK(counts[b] > 0);  // the test covers every band

  // The meridian: cutter as given; shank and holder stacked above it.
  REQUIRE(jp["cutter"].size() == p.meridian.size());
  for (size_t i = 0; i < p.meridian.size(); ++i) {
    CHECK(jp["cutter"][i][0].get<double>() == doctest::Approx(p.meridian[i].x()).epsilon(1e-9));
    CHECK(jp["cutter"][i][1].get<double>() == doctest::Approx(p.meridian[i].y()).epsilon(1e-9));
  }
  const double L = p.meridian.back().x();
  CHECK(jp["shank"] == nlohmann::json::parse("[[30.0,4.0],[50.0,4.0]]"));
  CHECK(jp["holder"] == nlohmann::json::parse("[[50.0,12.5],[90.0,20.0],[100.0,20.0]]"));
  CHECK(L == 30.0);

  // Axis ruled surface: rail a at the tip, rail b a cutter length along the axis.
  const std::vector<float> rails = floats(jp["rails"]);
  REQUIRE(rails.size() == 6 * p.poses.size());
  for (size_t i = 0; i < p.poses.size(); ++i) {
    const Eigen::Vector3d b = p.poses[i].tip + L * p.poses[i].axis;
    for (int c = 0; c < 3; ++c) {
      CHECK(rails[6 * i + c] == doctest::Approx(p.poses[i].tip[c]).epsilon(1e-6));
      CHECK(rails[6 * i + 3 + c] == doctest::Approx(b[c]).epsilon(1e-6));
    }
  }
  CHECK(jp["envelope"]["triangles"].get<size_t>() == p.envelope_mm.faces.size());

  // The track: tips, axes, programmed values, rapid flags, tool per frame.
  const ViewerTrack& t = s.tracks[0];
  const auto& jt = j["tracks"][0];
  CHECK(jt["name"] == "cone-1.ngc");
  CHECK(jt["axes"] == nlohmann::json::parse(R"(["X","Y","Z","A","C"])"));
  REQUIRE(jt["frames"].get<size_t>() == t.frames.size());
  const std::vector<float> tip = floats(jt["tip"]), axis = floats(jt["axis"]), values = floats(jt["values"]);
  const std::vector<std::uint8_t> rapid = unbase64(jt["rapid"]), patch = unbase64(jt["patch"]);
  REQUIRE(values.size() == 5 * t.frames.size());
  for (size_t i = 0; i < t.frames.size(); ++i) {
    CAPTURE(i);
    for (int c = 0; c < 3; ++c) {
      CHECK(tip[3 * i + c] == doctest::Approx(t.frames[i].pose.tip[c]).epsilon(1e-6));
      CHECK(axis[3 * i + c] == doctest::Approx(t.frames[i].pose.axis[c]).epsilon(1e-6));
    }
    for (int a = 0; a < 5; ++a) CHECK(values[5 * i + a] == doctest::Approx(t.frames[i].values[a]).epsilon(1e-6));
    CHECK(bool(rapid[i]) == t.frames[i].rapid);
    CHECK(u32_at(patch, i) == 0u);
  }
  // The marker jumps to the frame at its worst pose.
  REQUIRE(jp["markers"].size() == 1);
  CHECK(jp["markers"][0]["pose"] == 13);
  CHECK(jp["markers"][0]["frames"] == nlohmann::json::parse("[13]"));
  CHECK(jp["markers"][0]["label"] == "holder collides at poses 12-14, 0.731 mm deep");
}

TEST_CASE("viewer_json: the same scene gives the same bytes, a moved pose different ones") {
  const ViewerScene s = small_scene();
  const std::string a = viewer_json(s), b = viewer_json(small_scene());
  CHECK(a == b);
  CHECK(viewer_html(s) == viewer_html(small_scene()));
  ViewerScene moved = small_scene();
  moved.tracks[0].frames[5].pose.tip.x() += 0.5;
  CHECK(viewer_json(moved) != a);
}

TEST_CASE("viewer_track: the posted motion taken back to the part frame, the tool of each section") {
  Posted posted;
  posted.program.rotary_names = {"B", "C"};
  auto move = [](double x, bool rapid) {
    NcMove m;
    m.rapid = rapid;
    m.at.linear = Eigen::Vector3d(x, 2 * x, 3);
    m.at.rotary = {x / 10, -x};
    m.pose = {Eigen::Vector3d(x, 1, 2), Eigen::Vector3d(0, std::sin(0.1 * x), std::cos(0.1 * x))};
    return NcBlock(m);
  };
  auto& b = posted.program.blocks;
  b = {NcComment{"start"}, NcToolChange{1, "a"}, move(1, true), move(2, false), NcToolChange{2, "b"}, move(3, true),
       move(4, false), move(5, true)};  // the last move is the final retract, after the sections
  posted.sections = {{"second", {}, 1, 4, 0}, {"first", {}, 4, 7, 0}};
  // Setup: the part turned 90 degrees about Z and moved; the track must undo it.
  const Eigen::Matrix3d R_work_part = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d t_work_part(100, -50, 20);
  const Eigen::Matrix3d R = R_work_part.transpose();
  const ViewerTrack t = viewer_track(posted, "all.ngc", {"B", "C"}, R, -R * t_work_part, {"first", "second"});
  CHECK(t.name == "all.ngc");
  CHECK(t.axis_names[3] == "B");
  CHECK(t.axis_names[4] == "C");
  REQUIRE(t.frames.size() == 5);
  const int expected_patch[5] = {1, 1, 0, 0, 0};
  for (size_t i = 0; i < 5; ++i) {
    CAPTURE(i);
    const NcMove& m = std::get<NcMove>(b[i < 2 ? 2 + i : 3 + i]);
    const Eigen::Vector3d back = R_work_part * t.frames[i].pose.tip + t_work_part;
    CHECK((back - m.pose.tip).norm() < 1e-12);
    CHECK((R_work_part * t.frames[i].pose.axis - m.pose.axis).norm() < 1e-12);
    CHECK(t.frames[i].values[0] == m.at.linear.x());
    CHECK(t.frames[i].values[4] == m.at.rotary[1]);
    CHECK(t.frames[i].rapid == m.rapid);
    CHECK(t.frames[i].patch == expected_patch[i]);
  }
}

TEST_CASE("decimate keeps the triangle budget, maps every vertex nearby, and leaves small meshes alone") {
  const TriMesh grid = test::wavy_grid(317, 317, 200, 200, 10);  // ~200k triangles
  REQUIRE(grid.faces.size() > 199000);
  const Decimated same = decimate(grid, 300000);
  CHECK(same.mesh.faces == grid.faces);
  CHECK(same.mesh.vertices.size() == grid.vertices.size());
  for (int budget : {50000, 5000}) {
    CAPTURE(budget);
    const Decimated d = decimate(grid, budget);
    CHECK(d.mesh.faces.size() <= size_t(budget));
    CHECK(d.mesh.faces.size() >= size_t(budget / 4));  // not thrown away
    REQUIRE(d.vertex_map.size() == grid.vertices.size());
    // Cells of about sqrt(2 A / budget): no vertex moves farther than a few of them.
    const double cell = std::sqrt(2 * 200.0 * 200.0 / budget);
    double worst = 0;
    for (size_t i = 0; i < grid.vertices.size(); ++i) {
      REQUIRE(d.vertex_map[i] >= 0);
      REQUIRE(size_t(d.vertex_map[i]) < d.mesh.vertices.size());
      worst = std::max(worst, (grid.vertices[i] - d.mesh.vertices[size_t(d.vertex_map[i])]).norm());
    }
    CHECK(worst < 3 * cell);
    for (const auto& f : d.mesh.faces) CHECK((f[0] != f[1] && f[1] != f[2] && f[0] != f[2]));
    CHECK(decimate(grid, budget).mesh.vertices == d.mesh.vertices);  // deterministic
  }
}

TEST_CASE("a 200k-triangle surface and part give a page under 20 MB, within the triangle budgets" * doctest::test_suite("heavy")) {
  ViewerScene s = small_scene();
  s.surface_mm = test::wavy_grid(317, 317, 200, 200, 10);
  s.part_mm = test::wavy_grid(317, 317, 200, 200, 30);
  std::mt19937 rng;
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  s.patches[0].design_deviation_mm.clear();
  for (size_t i = 0; i < s.surface_mm.vertices.size(); ++i) s.patches[0].design_deviation_mm.push_back(u(rng));
  s.patches.push_back(s.patches[0]);
  s.patches.push_back(s.patches[0]);
  const ViewerOptions o;
  const std::string page = viewer_html(s, o);
  MESSAGE("page of a 200k-triangle surface and part with 3 patches: ", page.size() / 1e6, " MB");
  CHECK(page.size() < 20'000'000);
  const std::string json = viewer_json(s, o);
  const nlohmann::json j = nlohmann::json::parse(json);
  CHECK(j["surface"]["triangles"].get<int>() == int(s.surface_mm.faces.size()));  // within the default budget
  CHECK(j["part"]["triangles"].get<int>() <= o.max_part_triangles);
  CHECK(j["part"]["original_triangles"].get<size_t>() == s.part_mm.faces.size());
  // A tighter budget shrinks Φ and its bands with it.
  ViewerOptions tight;
  tight.max_surface_triangles = 20000;
  const nlohmann::json k = nlohmann::json::parse(viewer_json(s, tight));
  CHECK(k["surface"]["triangles"].get<int>() <= 20000);
  CHECK(unbase64(k["patches"][1]["bands"]).size() == k["surface"]["vertices"].get<size_t>());
}

TEST_CASE("viewer_html: one offline section with the ready/error hooks and the data, scripts inlined") {
  const std::string h = viewer_html(small_scene());
  CHECK(h.find("<section id=\"flankcam-view\">") == 0);
  CHECK(h.find("data-flankcam-viewer") != std::string::npos);
  CHECK(h.find(" src=") == std::string::npos);
  if (viewer_available()) {
    CHECK(h.find("id=\"fcv-data\"") != std::string::npos);
    CHECK(h.find("OrbitControls") != std::string::npos);
    CHECK(h.find("'ready'") != std::string::npos);
  } else {
    CHECK(h.find("error: three.js was not available") != std::string::npos);
  }
  // A label cannot end the data's <script>.
  ViewerScene s = small_scene();
  s.patches[0].name = "</script><b>";
  const std::string j = viewer_json(s);
  CHECK(j.find("</script>") == std::string::npos);
  CHECK(nlohmann::json::parse(j)["patches"][0]["name"] == "</script><b>");
}

TEST_CASE("viewer_json refuses an inconsistent scene, naming what is wrong") {
  ViewerScene s = small_scene();
  s.patches[0].design_deviation_mm.pop_back();
  CHECK_THROWS_WITH_AS(viewer_json(s), doctest::Contains("patch 'cone-1'"), InputError);
  s = small_scene();
  s.patches[0].markers[0].pose = 99;
  CHECK_THROWS_WITH_AS(viewer_json(s), doctest::Contains("marker pose 99"), InputError);
  s = small_scene();
  s.tracks[0].frames[3].patch = 4;
  CHECK_THROWS_WITH_AS(viewer_json(s), doctest::Contains("track 'cone-1.ngc'"), InputError);
  ViewerOptions o;
  o.max_frames = 1;
  CHECK_THROWS_WITH_AS(viewer_json(small_scene(), o), doctest::Contains("max_frames"), InputError);
}

TEST_CASE("viewer_json subsamples a long track to max_frames, keeping both ends") {
  ViewerScene s = small_scene();
  ViewerOptions o;
  o.max_frames = 7;
  const nlohmann::json j = nlohmann::json::parse(viewer_json(s, o));
  CHECK(j["tracks"][0]["frames"] == 7);
  CHECK(j["tracks"][0]["original_frames"] == 20);
  const std::vector<float> tip = floats(j["tracks"][0]["tip"]);
  CHECK(tip[0] == doctest::Approx(s.tracks[0].frames.front().pose.tip.x()));
  CHECK(tip[3 * 6] == doctest::Approx(s.tracks[0].frames.back().pose.tip.x()));
}

// verify.html's view (postproc/verify_view.h): a cone standing against a wall x = r(z) that it cuts
// exactly, moving along y; the CL-data pass as flank_program writes it, optionally with one pose
// pushed `into_mm` into the wall (a gouge on that GOTO's line).
namespace {

double cone_r(double z) { return 3 + 0.1 * z; }

TriMesh cone_wall() { return test::flank_wall(cone_r, 30, 60, 20); }

VerifyTool cone_tool() {
  VerifyTool t;
  std::vector<Eigen::Vector2d> meridian;
  for (int k = 0; k <= 20; ++k) meridian.emplace_back(1.0 * k, cone_r(1.0 * k));
  ToolAssembly holder;
  holder.shank_length = 10, holder.shank_diameter = 6;
  holder.holder_length = 20, holder.holder_diameter = 16, holder.holder_diameter_far = 24;
  t.assembly = assembly_from_meridian(meridian, holder);
  return t;
}

ClProgram wall_pass(int gouge_pose = -1, double into_mm = 0) {
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 20; ++i) poses.push_back({Eigen::Vector3d(0, -20 + 2.0 * i, 0), Eigen::Vector3d::UnitZ()});
  if (gouge_pose >= 0) poses[size_t(gouge_pose)].tip.x() += into_mm;
  return flank_program("WALL", poses, cone_tool().assembly.cutter, 600, 10000, 5, 30);
}

}  // namespace

TEST_CASE("verify view: one frame per simulated position, its pose, line and tool, the deviation verify computed") {
  const TriMesh wall = cone_wall();
  const SurfaceIndex part(wall);
  const VerifyTool tool = cone_tool();
  VerifyOptions o;
  o.gouge_tolerance_mm = 0.01;
  const ClProgram cl = wall_pass();
  const VerifyReport rep = verify_cl(cl, part, tool, o, &part);
  REQUIRE(rep.clean());
  REQUIRE(rep.positions > 100);
  REQUIRE(rep.motion.size() == size_t(rep.positions));
  const ViewerScene s = verify_view(wall, {}, 0.01, {{"wall.apt", &rep, {tool}, {"X", "Y", "Z", "A", "C"}, false}});
  REQUIRE(s.tracks.size() == 1);  // one program: no whole-run track
  CHECK(s.tracks[0].frames.size() == size_t(rep.positions));
  const nlohmann::json j = nlohmann::json::parse(viewer_json(s));
  const auto& t = j["tracks"][0];
  CHECK(t["original_frames"].get<long>() == rep.positions);
  REQUIRE(t["frames"].get<long>() == rep.positions);
  CHECK(t["has_values"] == false);
  const std::vector<float> tip = floats(t["tip"]), axis = floats(t["axis"]);
  const std::vector<std::uint8_t> lines = unbase64(t["line"]), rapid = unbase64(t["rapid"]);
  REQUIRE(tip.size() == 3 * size_t(rep.positions));
  for (size_t k = 0; k < rep.motion.size(); ++k) {
    CAPTURE(k);
    const VerifiedPosition& q = rep.motion[k];
    CHECK(tip[3 * k + 1] == doctest::Approx(q.pose.tip.y()).epsilon(1e-6));
    CHECK(axis[3 * k + 2] == doctest::Approx(q.pose.axis.z()).epsilon(1e-6));
    CHECK(u32_at(lines, k) == std::uint32_t(rep.blocks[size_t(q.block)].line));
    CHECK(bool(rapid[k]) == rep.blocks[size_t(q.block)].rapid);
  }
  // The frames run through every GOTO in order: the line numbers never decrease and reach the last.
  CHECK(u32_at(lines, rep.motion.size() - 1) == cl.moves.size());
  // The tool drawn is the one simulated, with its shank and holder; no Ω, no fitted poses.
  REQUIRE(j["patches"].size() == 1);
  CHECK(j["patches"][0]["cutter"].size() == tool.assembly.cutter.size());
  CHECK(j["patches"][0]["holder"][0][1].get<double>() == doctest::Approx(8));
  CHECK(j["patches"][0]["bands"].is_null());
  CHECK(j["patches"][0]["envelope"].is_null());
  CHECK(j["patches"][0]["poses"] == 0);
  // The surface coloured by the machined deviation verify computed: its bands, vertex by vertex.
  REQUIRE(j["colourings"].size() == 1);
  const std::vector<std::uint8_t> bands = unbase64(j["colourings"][0]["bands"]), all = unbase64(j["bands"]);
  REQUIRE(bands.size() == wall.vertices.size());
  int within = 0;
  for (size_t v = 0; v < bands.size(); ++v) {
    CHECK(bands[v] == std::uint8_t(deviation_band(rep.design.deviation_mm[v], 0.01)));
    CHECK(all[v] == bands[v]);
    within += bands[v] == std::uint8_t(DeviationBand::Within);
  }
  CHECK(within == rep.design.within);
  CHECK(within > 100);
}

TEST_CASE("verify view: a gouge is a marker labelled with its program line that jumps to its deepest position") {
  const TriMesh wall = cone_wall();
  const SurfaceIndex part(wall);
  const VerifyTool tool = cone_tool();
  VerifyOptions o;
  const ClProgram clean = wall_pass(), bad = wall_pass(10, 0.5);
  const VerifyReport a = verify_cl(clean, part, tool, o, &part), b = verify_cl(bad, part, tool, o, &part);
  REQUIRE(a.clean());
  REQUIRE_FALSE(b.clean());
  const std::vector<VerifyViewProgram> programs = {{"clean.apt", &a, {tool}, {"X", "Y", "Z", "A", "C"}, false},
                                                   {"bad.apt", &b, {tool}, {"X", "Y", "Z", "A", "C"}, false}};
  const ViewerScene s = verify_view(wall, {}, 0.01, programs);
  REQUIRE(s.tracks.size() == 3);  // each program and the whole run
  CHECK(s.tracks[2].frames.size() == size_t(a.positions + b.positions));
  for (const ViewerOptions& vo : {ViewerOptions{}, ViewerOptions{100, 100, 100, 40, 100}}) {  // whole and subsampled
    CAPTURE(vo.max_frames);
    const nlohmann::json j = nlohmann::json::parse(viewer_json(s, vo));
    REQUIRE(j["patches"].size() == 2);
    const auto& markers = j["patches"][1]["markers"];
    REQUIRE(markers.size() == b.hits.size());
    CHECK(j["patches"][0]["markers"].empty());
    for (size_t m = 0; m < b.hits.size(); ++m) {
      const VerifyHit& h = b.hits[m];
      CAPTURE(h.line);
      CHECK(markers[m]["label"].get<std::string>().rfind("bad.apt line " + std::to_string(h.line) + ": tool gouge ", 0) == 0);
      CHECK(markers[m]["at"][0].get<double>() == doctest::Approx(h.point.x()));
      // The jump lands on the deepest position in the program's track and in the whole run's, not in the clean one.
      const auto& frames = markers[m]["frames"];
      CHECK(frames[0] == -1);
      for (size_t t : {size_t(1), size_t(2)}) {
        const int f = frames[t];
        REQUIRE(f >= 0);
        const std::vector<float> tip = floats(j["tracks"][t]["tip"]);
        const std::vector<std::uint8_t> lines = unbase64(j["tracks"][t]["line"]);
        CHECK(tip[3 * size_t(f)] == doctest::Approx(b.motion[size_t(h.position)].pose.tip.x()));
        CHECK(tip[3 * size_t(f) + 1] == doctest::Approx(b.motion[size_t(h.position)].pose.tip.y()));
        CHECK(u32_at(lines, size_t(f)) == std::uint32_t(h.line));
      }
    }
    // The gouged line is the moved GOTO or its neighbours (the cutter sweeps into and out of it).
    bool moved_line = false;
    for (const VerifyHit& h : b.hits) moved_line |= bad.moves[size_t(h.line - 1)].pose.tip.x() > 0.4;
    CHECK(moved_line);
  }
}

TEST_CASE("verify view: an NC program's frames carry the programmed axis values, interpolated as the controller does") {
  const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const TriMesh wall = cone_wall();
  const SurfaceIndex part(wall);
  VerifyTool tool = cone_tool();
  tool.length_mm = 80;
  std::vector<NcPoint> pts(3);
  pts[0].line = 5, pts[0].rapid = true, pts[0].at.linear = {0, -60, 120}, pts[0].known = 31;
  pts[1].line = 6, pts[1].at = {{10, -60, 120}, {20, 30}}, pts[1].known = 31, pts[1].f = 500;
  pts[2].line = 8, pts[2].at = {{10, -50, 110}, {20, 90}}, pts[2].known = 31, pts[2].f = 500;
  const VerifyReport rep = verify_program(pts, m, false, part, {tool}, {});
  REQUIRE(rep.motion.size() == size_t(rep.positions));
  const ViewerScene s = verify_view(wall, {}, 0.01, {{"p.ngc", &rep, {tool}, {"X", "Y", "Z", "A", "C"}, true}});
  const nlohmann::json j = nlohmann::json::parse(viewer_json(s));
  const auto& t = j["tracks"][0];
  CHECK(t["has_values"] == true);
  CHECK(t["axes"][4] == "C");
  REQUIRE(t["frames"].get<long>() == rep.positions);
  const std::vector<float> values = floats(t["values"]), tip = floats(t["tip"]);
  const std::vector<std::uint8_t> lines = unbase64(t["line"]);
  size_t ends = 0;
  for (size_t k = 0; k < rep.motion.size(); ++k) {
    CAPTURE(k);
    const VerifiedPosition& q = rep.motion[k];
    const NcPoint& to = pts[size_t(q.block)];
    CHECK(u32_at(lines, k) == std::uint32_t(to.line));
    // Each value between the block's start and end, the same fraction of the way for all five.
    const NcPoint& from = pts[size_t(std::max(q.block - 1, 0))];
    const double f = q.block == 0 ? 1 : (q.programmed.rotary[1] - from.at.rotary[1]) / (to.at.rotary[1] - from.at.rotary[1]);
    for (int a = 0; a < 3; ++a)
      CHECK(values[5 * k + size_t(a)] == doctest::Approx((1 - f) * from.at.linear[a] + f * to.at.linear[a]).epsilon(1e-5));
    CHECK(values[5 * k + 3] == doctest::Approx((1 - f) * from.at.rotary[0] + f * to.at.rotary[0]).epsilon(1e-5));
    // The pose drawn is the machine's forward kinematics of those values.
    const ToolPose fk = forward(m, q.programmed, tool.length_mm);
    CHECK(tip[3 * k] == doctest::Approx(fk.tip.x()).epsilon(1e-5));
    CHECK(tip[3 * k + 2] == doctest::Approx(fk.tip.z()).epsilon(1e-5));
    if (k + 1 == rep.motion.size() || rep.motion[k + 1].block != q.block) {
      ++ends;
      CHECK(values[5 * k + 4] == doctest::Approx(to.at.rotary[1]));
    }
  }
  CHECK(ends == 3);
  // The machine mode's chain: the machine file's axes in chain order and each patch's tool length.
  const ViewerScene sm = verify_view(wall, {}, 0.01, {{"p.ngc", &rep, {tool}, {"X", "Y", "Z", "A", "C"}, true}}, &m);
  const nlohmann::json jm = nlohmann::json::parse(viewer_json(sm));
  REQUIRE(jm["machine"].is_object());
  CHECK(jm["machine"]["name"] == "xyzac-trt");
  for (size_t k = 0; k < 2; ++k) {
    CAPTURE(k);
    CHECK(jm["machine"]["rotary"][k]["name"] == m.rotary[k].name);
    CHECK(jm["machine"]["rotary"][k]["table"] == (m.rotary[k].carries == Carrier::Table));
    for (int c = 0; c < 3; ++c) {
      CHECK(jm["machine"]["rotary"][k]["pivot"][size_t(c)].get<double>() == doctest::Approx(m.rotary[k].pivot[c]));
      CHECK(jm["machine"]["rotary"][k]["direction"][size_t(c)].get<double>() == doctest::Approx(m.rotary[k].direction[c]));
    }
  }
  CHECK(jm["machine"]["tool_length_mm"] == nlohmann::json::array({80.0}));
  CHECK(j["machine"].is_null());
  ViewerScene bad = sm;
  bad.machine->tool_length_mm.push_back(50);
  CHECK_THROWS_WITH_AS(viewer_json(bad), doctest::Contains("2 tool lengths for 1 patches"), InputError);
}

TEST_CASE("verify view refuses a marker that jumps outside its track") {
  ViewerScene s = small_scene();
  s.patches[0].markers[0].frames = {20};
  CHECK_THROWS_WITH_AS(viewer_json(s), doctest::Contains("frame 20 of 20"), InputError);
  s.patches[0].markers[0].frames = {19, 0};
  CHECK_THROWS_WITH_AS(viewer_json(s), doctest::Contains("frames for 2 of 1 tracks"), InputError);
  s.patches[0].markers[0].frames = {-1};
  s.patches[0].markers[0].pose = 99;  // unused once the frames are given
  CHECK_NOTHROW((void)viewer_json(s));
}

TEST_CASE("verify view of a 200k-triangle surface and part with eight long programs: a page under 20 MB, the hits' frames kept" * doctest::test_suite("heavy")) {
  const TriMesh surface = test::wavy_grid(317, 317, 200, 200, 10), part = test::wavy_grid(317, 317, 200, 200, 30);
  REQUIRE(surface.faces.size() > 199000);
  // Eight programs of 30000 simulated positions each, as verify reports them (no simulation here).
  std::mt19937 rng;
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::vector<VerifyReport> reports(8);
  std::vector<VerifyViewProgram> programs;
  for (size_t k = 0; k < reports.size(); ++k) {
    VerifyReport& r = reports[k];
    for (int b = 0; b < 300; ++b) r.blocks.push_back({b, 10 + b, b % 50 == 0, 1, {}, 0.01});
    for (int i = 0; i < 30000; ++i) {
      const double s = i / 30000.0;
      r.motion.push_back({{Eigen::Vector3d(200 * s - 100, 10.0 * k, 5), Eigen::Vector3d::UnitZ()}, {}, i / 100});
    }
    r.positions = long(r.motion.size());
    r.hits.push_back({});
    r.hits.back().position = 12345 + int(k), r.hits.back().line = 10 + (12345 + int(k)) / 100;
    r.design.deviation_mm.resize(surface.vertices.size());
    for (double& d : r.design.deviation_mm) d = u(rng);
    programs.push_back({"p" + std::to_string(k) + ".nc", &r, {cone_tool()}, {"X", "Y", "Z", "B", "C"}, true});
  }
  const ViewerScene s = verify_view(surface, part, 0.01, programs);
  REQUIRE(s.tracks.size() == 9);
  const ViewerOptions o;
  const std::string page = viewer_html(s, o);
  MESSAGE("verify page of a 200k-triangle surface and part, 8 programs of 30000 positions: ", page.size() / 1e6, " MB");
  CHECK(page.size() < 20'000'000);
  const nlohmann::json j = nlohmann::json::parse(viewer_json(s, o));
  long frames = 0;
  for (const auto& t : j["tracks"]) frames += t["frames"].get<long>();
  CHECK(frames <= o.max_total_frames + 2 * 8);  // the shares, and each hit's frame in its track and the whole run
  CHECK(j["tracks"][8]["original_frames"] == 240000);
  for (size_t k = 0; k < reports.size(); ++k) {
    CAPTURE(k);
    const auto& m = j["patches"][k]["markers"][0];
    CHECK(m["label"].get<std::string>().rfind("p" + std::to_string(k) + ".nc line " + std::to_string(reports[k].hits[0].line) + ":", 0) == 0);
    for (size_t t : {k, size_t(8)}) {
      const int f = m["frames"][t];
      REQUIRE(f >= 0);
      const std::vector<float> tip = floats(j["tracks"][t]["tip"]);
      CHECK(tip[3 * size_t(f)] == doctest::Approx(reports[k].motion[size_t(reports[k].hits[0].position)].pose.tip.x()));
      CHECK(tip[3 * size_t(f) + 1] == doctest::Approx(10.0 * k));
    }
  }
}
