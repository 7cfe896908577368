// tool.end and depth_cuts in jobs (issue 15): the keys, the end in every tool file, and depth
// levels as sections of the program on the bundled blade.
#include <doctest/doctest.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/check_surface.h"
#include "core/errors.h"
#include "core/mesh.h"
#include "core/number_format.h"
#include "pipeline/run.h"
#include "postproc/gcode.h"
#include "postproc/tool_export.h"
#include "tests/pipeline/job_error.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// One patch of the bundled blade (the passes test's), cone tool, iso on xyzbc-head-table.
std::string blade_job(const std::string& extra) {
  const std::string ex = std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/";
  return "surface: " + ex + "blade.obj\ntolerance: 0.015\nsampling: {s: 20, t: 60}\n" + extra +
         "machine: xyzbc-head-table\npost: {dialects: [iso]}\n"
         "patches:\n  - name: blade\n    init: lines\n    lines:\n"
         "      - [5.350, 10.342, -1.086, 0.669, 10.353, 60.944]\n"
         "      - [10.691, 10.006, -1.233, 4.819, 11.629, 60.825]\n"
         "      - [15.884, 9.359, -1.377, 8.927, 12.621, 60.707]\n";
}

// A block the fit never saw, 0.25 mm off the shank's side away from the blade, 5 mm above the
// cutter's end at `pose`, from `back` mm behind it to `ahead` mm ahead of it along the motion (x).
TriMesh shank_block(const pipeline::FittedPatch& p, size_t pose, double back, double ahead) {
  const ToolPose& at_pose = p.poses.at(pose);
  const double L = p.assembly.cutter_length(), rs = 0.5 * p.assembly.shank_diameter;
  const Eigen::Vector3d axis = at_pose.axis.normalized(), at = at_pose.tip + (L + 5) * axis;
  const double side = (at_pose.tip + 0.5 * L * axis - p.contacts.at(pose)).y() > 0 ? 1 : -1;
  const double forward = p.poses.back().tip.x() > p.poses.front().tip.x() ? 1 : -1;
  double face = -INFINITY;  // the shank's outermost y towards `side` over z in [L + 4, L + 6]
  for (double z = L + 4; z <= L + 6; z += 0.1) face = std::max(face, side * (at_pose.tip + z * axis).y() + rs);
  const double y0 = side * (face + 0.25), y1 = side * (face + 2);
  const double xa = at.x() - forward * back, xb = at.x() + forward * ahead;
  return test::box_mesh({std::min(xa, xb), std::min(y0, y1), at.z() - 0.5}, {std::max(xa, xb), std::max(y0, y1), at.z() + 0.5});
}

pipeline::RunResult run_job(const test::ScratchDir& dir, const std::string& yaml) {
  test::write_text(dir.file("job.yaml"), yaml);
  pipeline::Job j = pipeline::read_job(dir.file("job.yaml"));
  const Machine machine = pipeline::check_run(j);
  return pipeline::run(std::move(j), machine, {});
}
}  // namespace

TEST_CASE("tool.end and depth_cuts in a job are checked with file, line and key") {
  test::ScratchDir dir("tool-end-keys");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const std::string rest = "surface: s.obj\npatches:\n  - name: p\n    init: line\n    line: [0, 0, 0, 0, 0, 10]\n";
  const struct {
    const char* key;
    const char* expect;
  } cases[] = {
      {"tool: {end: round}", ":1: tool.end: unknown end 'round': expected flat, ball or {corner: R}"},
      {"tool: {end: corner}", ":1: tool.end: corner needs its radius"},
      {"tool: {end: {corner: -1}}", ":1: tool.end.corner: must be > 0"},
      {"tool: {end: {corner: x}}", ":1: tool.end.corner: expected a number"},
      {"tool: {end: {radius: 2}}", ":1: tool.end.radius: unknown key"},
      {"tool: {end: [1, 2]}", ":1: tool.end: expected flat, ball or {corner: R}"},
      {"tool: {catalogue: cyl-d6-l20, end: {corner: 4}}", ":1: tool.end.corner: 4.0000 mm is larger than the tool's ball radius 3.0000 mm"},
      {"depth_cuts: 0", ":1: depth_cuts: expected a whole number in 1..50"},
      {"depth_cuts: 51", ":1: depth_cuts: expected a whole number in 1..50"},
      {"depth_cuts: 2.5", ":1: depth_cuts: expected a whole number in 1..50"},
      {"depth_cuts: many", ":1: depth_cuts: expected a number"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.key);
    test::write_text(dir.file("job.yaml"), std::string(c.key) + "\n" + rest);
    const std::string msg = test::job_error(dir.file("job.yaml"));
    CAPTURE(msg);
    CHECK(msg.find(dir.file("job.yaml") + c.expect) != std::string::npos);
  }
  test::write_text(dir.file("job.yaml"), "tool: {catalogue: cyl-d6-l20, end: {corner: 3}}\ndepth_cuts: 50\n" + rest);
  const pipeline::Job ok = pipeline::read_job(dir.file("job.yaml"));
  CHECK(ok.tool.end.kind == EndKind::Corner);
  CHECK(ok.tool.end.corner_radius == 3);
  CHECK(ok.depth_cuts == 50);
  test::write_text(dir.file("job.yaml"), "tool: {end: ball}\n" + rest);
  CHECK(pipeline::read_job(dir.file("job.yaml")).tool.end.kind == EndKind::Ball);
  test::write_text(dir.file("job.yaml"), rest);
  CHECK(pipeline::read_job(dir.file("job.yaml")).tool.end.kind == EndKind::Flat);  // the default
}

TEST_CASE("a corner end is in the profile, the collision cutter, the grinding sheet, the DXF and the report, and costs the fillet band's coverage" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("tool-end-corner");
  const pipeline::RunResult flat = run_job(dir, blade_job("tool: {shape: cone}\n"));
  const pipeline::RunResult bull = run_job(dir, blade_job("tool: {shape: cone, end: {corner: 1.5}}\n"));
  const pipeline::FittedPatch &f = flat.fit.fitted.patches.at(0), &b = bull.fit.fitted.patches.at(0);
  CHECK(f.end_points == 0);
  REQUIRE(b.end_points == 16);
  CHECK(b.end_radius_mm == 1.5);
  // The arc: from the tip plane (z of the flat tool's tip face) to the side, all 1.5 mm from one centre.
  const Eigen::Vector2d tip = b.profile_mm.front(), tangent = b.profile_mm[16];
  const Eigen::Vector2d centre(tip.x() + 1.5, tip.y());
  for (int k = 0; k <= 16; ++k) CHECK((b.profile_mm[size_t(k)] - centre).norm() == doctest::Approx(1.5).epsilon(1e-6));
  CHECK(tip.y() < tangent.y() - 1.0);  // the tip face shrank by about the corner radius
  // The collision check's cutter is that profile (from z = 0), the fitted side above it.
  CHECK(b.assembly.cutter.front().y() < tangent.y() - 0.5);
  CHECK(b.assembly.cutter.back().y() == doctest::Approx(b.profile_mm.back().y()));
  // Files: the DXF's profile starts with the tip face down to the axis and runs through the arc.
  const std::string dxf = tool_dxf(b.profile_mm, "bull");
  CHECK(dxf.find("10\n" + fixed(tip.x(), 6) + "\n20\n0.000000\n30\n0.0\n11\n" + fixed(tip.x(), 6) + "\n21\n" +
                 fixed(tip.y(), 6)) != std::string::npos);
  const std::string sheet = pipeline::tool_sheet(bull.fit.job, b);
  CHECK(sheet.find("end_corner_radius_mm,1.5000") != std::string::npos);
  const ToolDimensions df = tool_dimensions(f.profile_mm), db = tool_dimensions(b.profile_mm, b.end_points);
  CHECK(db.cone_half_angle_deg == doctest::Approx(df.cone_half_angle_deg).epsilon(0.05));
  const nlohmann::ordered_json report = pipeline::patch_report(bull.fit.job, bull.fit.fitted, b);
  CHECK(report["tool"]["end"]["kind"] == "corner");
  CHECK(report["tool"]["end"]["radius_mm"] == 1.5);
  // The machined surface: the fillet band (height ~R at the flank's bottom) is the torus's, not the flank's.
  int by_end = 0;
  for (char e : b.fit.machined.design_by_end) by_end += e;
  MESSAGE("coverage within 0.015 mm: flat end " << f.fit.coverage << ", corner 1.5 mm " << b.fit.coverage << "; "
                                                << by_end << " vertices machined by the torus");
  CHECK(by_end > 0);
  CHECK(b.fit.coverage <= f.fit.coverage + 1e-9);
  // APT-7 CUTTER: the corner radius and its centre (e radial, f axial); the flat tool has none.
  REQUIRE(bull.fit.cl_data.at(0));
  const AptCutter& cut = bull.fit.cl_data[0]->cutter;
  CHECK(cut.r == 1.5);
  CHECK(cut.e == doctest::Approx(tip.y()));
  CHECK(cut.f == doctest::Approx(tip.x() + 1.5));
  CHECK(cut.d == doctest::Approx(flat.fit.cl_data.at(0)->cutter.d).epsilon(1e-6));  // the same side cone
  CHECK(flat.fit.cl_data[0]->cutter.r == 0);
  // Programs were posted for both (the back-simulation swept the profile with its end).
  CHECK(!flat.programs.empty());
  CHECK(!bull.programs.empty());
}

TEST_CASE("a ball end on the blade's general tool: the checks' cutter starts on the axis, programs are posted" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("tool-end-ball");
  const pipeline::RunResult ball = run_job(dir, blade_job("tool: {shape: general, end: ball}\n"));
  const pipeline::FittedPatch& b = ball.fit.fitted.patches.at(0);
  REQUIRE(b.end_points == 16);
  CHECK(b.profile_mm.front().y() == 0);
  CHECK(b.assembly.cutter.front() == Eigen::Vector2d(0, 0));
  CHECK(b.assembly.validate().empty());
  CHECK(b.end_radius_mm > 0.5 * b.profile_mm[16].y());
  // Its top is the flat end's: the cutter ends at the axis end, where the fit put shank and holder
  // (the side meridian alone ends d(1) sin a short of it on a tool widening towards its holder).
  const double axis_mm = ball.fit.fitted.frame.length_to_mm(b.fit.fit.rails.length);
  CHECK(b.assembly.cutter_length() == doctest::Approx(axis_mm).epsilon(1e-12));
  CHECK(b.profile_mm.back().x() == doctest::Approx(axis_mm).epsilon(1e-12));
  const std::vector<Eigen::Vector2d> side = meridian(b.fit.fit.tool, b.fit.fit.rails.length);
  MESSAGE("side meridian ends " << axis_mm - ball.fit.fitted.frame.length_to_mm(side.back().x()) << " mm below the axis end");
  MESSAGE("ball radius " << b.end_radius_mm << " mm on a tip radius " << b.profile_mm[16].y() << " mm; coverage " << b.fit.coverage);
  CHECK(!ball.programs.empty());
}

TEST_CASE("depth_cuts: 3 makes three sections of the patch's program, the tip 2/3 and 1/3 of the cutting length higher, the deepest last" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("depth-cuts");
  const pipeline::RunResult run = run_job(dir, blade_job("tool: {shape: cone}\ndepth_cuts: 3\n"));
  const pipeline::FittedPatch& p = run.fit.fitted.patches.at(0);
  REQUIRE(run.fit.cl_data.at(0));
  REQUIRE(run.posted_cl.at(0));
  const ClProgram &final_cl = *run.fit.cl_data[0], &all = *run.posted_cl[0];
  // The cut of each level: the moves with a contact (the links, planned per section, have none).
  const auto cut = [](const ClProgram& cl) {
    std::vector<ToolPose> out;
    for (const ClMove& mv : cl.moves)
      if (mv.contact.allFinite()) out.push_back(mv.pose);
    return out;
  };
  const std::vector<ToolPose> fitted = cut(final_cl), levels = cut(all);
  const size_t n = fitted.size();
  REQUIRE(n > 10);
  REQUIRE(levels.size() == 3 * n);
  const double H = p.assembly.cutter_length();
  double worst_lift = 0, worst_off = 0;
  for (int level = 1; level <= 3; ++level) {
    double off_min = INFINITY, off_max = 0;
    for (size_t i = 0; i < n; ++i) {
      const ToolPose &q = levels[size_t(level - 1) * n + i], &f = fitted[i];
      const Eigen::Vector3d e = f.axis.normalized(), d = q.tip - f.tip;
      CHECK((q.axis - f.axis).norm() < 1e-12);
      worst_lift = std::max(worst_lift, std::abs(d.dot(e) - H * (3 - level) / 3.0));
      const double off = (d - d.dot(e) * e).norm();
      off_min = std::min(off_min, off), off_max = std::max(off_max, off);
    }
    worst_off = std::max(worst_off, off_max - off_min);  // one radial offset per level
    if (level == 3) CHECK(off_max < 1e-12);             // the last level is the fitted motion
    MESSAGE("level " << level << ": lift " << H * (3 - level) / 3.0 << " mm, radial offset " << off_max << " mm");
  }
  CHECK(worst_lift < 1e-9);
  CHECK(worst_off < 1e-9);
  // Each level has its own links, as its section of the program: down the tool axis from `retract`
  // (50 mm, the default) above its lead point, fed in across the axis (at least the clearance, 1 mm).
  int entries = 0;
  for (size_t i = 0; i + 2 < all.moves.size(); ++i) {
    if (!all.moves[i].rapid || !all.moves[i + 1].rapid || all.moves[i + 2].rapid) continue;
    ++entries;
    const Eigen::Vector3d e = all.moves[i + 1].pose.axis.normalized();
    const Eigen::Vector3d down = all.moves[i + 1].pose.tip - all.moves[i].pose.tip, in = all.moves[i + 2].pose.tip - all.moves[i + 1].pose.tip;
    CHECK((down + 50 * e).norm() < 1e-6);
    CHECK((in - in.dot(e) * e).norm() >= 1);
  }
  CHECK(entries == 3);
  // One program, three sections in order, one tool change.
  int programs = 0;
  for (const pipeline::PostedProgram& w : run.programs) {
    if (w.patch != "blade") continue;
    ++programs;
    REQUIRE(w.posted.sections.size() == 3);
    const std::string text = nc_text(w.posted.program, {w.dialect, false, 0.005});
    const size_t l1 = text.find("DEPTH CUT 1 OF 3"), l2 = text.find("DEPTH CUT 2 OF 3"), l3 = text.find("DEPTH CUT 3 OF 3");
    REQUIRE(l1 != std::string::npos);
    REQUIRE(l2 != std::string::npos);
    REQUIRE(l3 != std::string::npos);
    CHECK(l1 < l2);
    CHECK(l2 < l3);
  }
  CHECK(programs == 1);
}

TEST_CASE("flankcam run: a cut whose end has no clear lead is shortened to where it can be left, its coverage judged anew" *
          doctest::test_suite("heavy")) {
  // The blade's patch fitted without a part; then a block beside the last third of that motion, 0.5 mm
  // beyond the cutter's widest side, the part with the blade: the cut itself stays clear (the fit
  // keeps the same motion), but off its last poses every lead candidate runs the cutter into the block
  // or keeps it on the flank in the rapid up its axis. The run shortens the cut to the last pose that
  // can be left, judges its coverage anew and posts clean programs.
  test::ScratchDir dir("lead-trim");
  const std::string job = blade_job("tool: {shape: cone}\n");
  test::write_text(dir.file("plain.yaml"), job);
  const pipeline::FitRun plain = pipeline::fit(pipeline::read_job(dir.file("plain.yaml")), {});
  const pipeline::FittedPatch& p0 = plain.fitted.patches.at(0);
  const size_t n = p0.poses.size();
  REQUIRE(n > 20);
  double r_max = 0, h = 0;
  for (const Eigen::Vector2d& zr : p0.profile_mm) r_max = std::max(r_max, zr.y()), h = std::max(h, zr.x());
  // The tool's side of the blade at the end (the blade's flank runs along x, its normal along y).
  const ToolPose& end = p0.poses.back();
  const double side = (end.tip + 0.5 * h * end.axis - p0.contacts.back()).y() > 0 ? 1 : -1;
  const size_t from = 2 * n / 3;
  double x0 = INFINITY, x1 = -INFINITY, near = -INFINITY, z0 = INFINITY, z1 = -INFINITY;
  for (size_t i = from; i < n; ++i)
    for (double z = 0; z <= h; z += 0.5) {
      const Eigen::Vector3d c = p0.poses[i].tip + z * p0.poses[i].axis.normalized();
      x0 = std::min(x0, c.x()), x1 = std::max(x1, c.x()), z0 = std::min(z0, c.z()), z1 = std::max(z1, c.z());
      near = std::max(near, side * c.y() + r_max);
    }
  const double y_near = side * (near + 0.5), y_far = side * (near + 3);
  const double forward = end.tip.x() > p0.poses.front().tip.x() ? 1 : -1;  // the motion's direction along x
  if (forward > 0) x1 += 15;
  else x0 -= 15;
  const TriMesh block = test::box_mesh({x0, std::min(y_near, y_far), z0 - 2}, {x1, std::max(y_near, y_far), z1 - 2});
  write_obj(dir.file("part.obj"), merged(load_mesh(std::string(FLANKCAM_SOURCE_DIR) + "/examples/blade/blade.obj").mesh, block));
  test::write_text(dir.file("job.yaml"), "part: part.obj\n" + job);
  pipeline::Job j = pipeline::read_job(dir.file("job.yaml"));
  const Machine machine = pipeline::check_run(j);
  std::vector<std::string> progress;
  pipeline::RunOptions o;
  o.progress = [&](const std::string& s) { progress.push_back(s); };
  const pipeline::RunResult run = pipeline::run(std::move(j), machine, o);
  const pipeline::FittedPatch& p = run.fit.fitted.patches.at(0);
  INFO(p.kept_for_leads);
  REQUIRE_FALSE(p.kept_for_leads.empty());
  CHECK(p.kept_for_leads.find("no lead-out off CL move") != std::string::npos);
  // Shortened at its end only, to the poses before the block (give or take the lead and the cutter).
  CHECK(p.poses.front().tip.isApprox(p0.poses.front().tip, 1e-9));
  CHECK(p.poses.size() < n);
  CHECK(p.poses.size() > from / 2);
  CHECK(p.fit.t_from == doctest::Approx(p0.fit.t_from));
  CHECK(p.fit.t_to < p0.fit.t_to);
  // Judged anew: the coverage lost what the dropped poses machined, and only that: every vertex within
  // the tolerance before and not after lies nearer the dropped poses' axes than the kept ones'.
  CHECK(p.fit.coverage < p0.fit.coverage - 0.02);
  CHECK(p.fit.coverage > 0.4 * p0.fit.coverage);
  const auto& verts = run.fit.fitted.surface.mesh.vertices;
  const double tol = run.fit.fitted.frame.length_to_unit(0.015);
  const auto axis_distance = [&](const Eigen::Vector3d& v, size_t i0, size_t i1) {
    double best = INFINITY;
    for (size_t i = i0; i < i1; ++i) {
      const Eigen::Vector3d e = p0.poses[i].axis.normalized(), d = v - p0.poses[i].tip;
      best = std::min(best, (d - d.dot(e) * e).norm());
    }
    return best;
  };
  const size_t kept = p.poses.size();
  int lost = 0, lost_near_kept = 0;
  for (size_t v = 0; v < verts.size(); ++v) {
    const double d = p.fit.machined.design_deviation[v], d0 = p0.fit.machined.design_deviation[v];
    if (!(std::isfinite(d0) && std::abs(d0) <= tol) || (std::isfinite(d) && std::abs(d) <= tol)) continue;
    ++lost;
    lost_near_kept += axis_distance(verts[v], 0, kept) < axis_distance(verts[v], kept, n);
  }
  MESSAGE("coverage ", p0.fit.coverage, " -> ", p.fit.coverage, ", ", lost, " vertices lost, ", lost_near_kept, " of them nearer the kept poses");
  CHECK(lost > 0);
  CHECK(lost_near_kept <= lost / 20);  // the seam: a vertex between the last kept and the first dropped pose
  // The program: its cut is the kept poses, it was back-simulated clean with its links.
  REQUIRE(run.posted_cl.at(0));
  std::vector<ToolPose> cut;
  for (const ClMove& mv : run.posted_cl[0]->moves)
    if (mv.contact.allFinite()) cut.push_back(mv.pose);
  REQUIRE(cut.size() == p.poses.size());
  CHECK(cut.back().tip.isApprox(p.poses.back().tip, 1e-6));
  bool posted = false;
  for (const pipeline::PostedProgram& w : run.programs) {
    CHECK(w.posted.refused.empty());
    CHECK(w.posted.links_checked);
    posted = posted || w.patch == "blade";
  }
  CHECK(posted);
  CHECK(std::any_of(progress.begin(), progress.end(), [](const std::string& s) { return s.find("kept (t ") != std::string::npos; }));
}

TEST_CASE("a patch refused for collisions is left out of the cover's union: the surface it would cut is not counted" *
          doctest::test_suite("heavy")) {
  // Two patches of the blade: the whole motion (0) and its first quarter (1). A block off the shank
  // at the whole motion's middle pose: patch 0 collides there, its longest clear stretch is under
  // three quarters of it, so it is refused (no program); patch 1 stays clear of it. The cover (as for
  // patches: auto) must then be what patch 1 alone machines.
  test::ScratchDir dir("refused-cover");
  test::write_text(dir.file("job.yaml"), blade_job("tool: {shape: cone, end: {corner: 1}}\nholder: {shank_length: 20, "
                                                   "shank_diameter: 6, length: 30, diameter: 20}\nclearance: 0.5\n"));
  pipeline::Job job = pipeline::read_job(dir.file("job.yaml"));
  job.cover.emplace();
  const pipeline::FitRun fitted = pipeline::fit(pipeline::read_job(dir.file("job.yaml")), {});  // owns the patches' jobs
  pipeline::FittedJob f = fitted.fitted;
  REQUIRE(f.patches.size() == 1);
  const size_t n = f.patches[0].poses.size();
  std::vector<std::string> progress;
  const auto log = [&](const std::string& s) { progress.push_back(s); };
  f.patches.push_back(f.patches[0]);
  std::vector<std::optional<pipeline::KeptPoses>> keep(2);
  keep[1] = pipeline::KeptPoses{0, n / 4, "its first quarter"};
  pipeline::keep_poses(job, f, keep, &pipeline::FittedPatch::kept_clear, "for the test", log);
  f.cover.emplace();
  f.check_part = shank_block(f.patches[0], n / 2, 0.5, 3);
  pipeline::check_job(job, f, log);
  REQUIRE_FALSE(f.patches[0].collisions.clear());
  REQUIRE(f.patches[1].collisions.clear());
  pipeline::shorten_to_clear(job, f, log);
  CHECK(f.patches[0].kept_clear.empty());  // no clear stretch of three quarters: not shortened
  pipeline::refuse_colliding(job, f, log);
  const pipeline::FittedPatch &whole = f.patches[0], &quarter = f.patches[1];
  CHECK(whole.refused);
  CHECK_FALSE(quarter.refused);
  const pipeline::CoverResult& c = *f.cover;
  MESSAGE("own coverage: whole " << whole.fit.coverage << ", quarter " << quarter.fit.coverage << "; cover " << c.coverage);
  CHECK(std::count_if(f.patches.begin(), f.patches.end(), [](const pipeline::FittedPatch& p) { return p.refused; }) == 1);
  CHECK(quarter.fit.coverage < 0.5 * whole.fit.coverage);
  CHECK(c.coverage == doctest::Approx(quarter.fit.coverage).epsilon(1e-12));
  CHECK(std::none_of(c.owner.begin(), c.owner.end(), [](int o) { return o == 0; }));
  CHECK(std::count(c.owner.begin(), c.owner.end(), 1) > 0);
  const std::string summary = pipeline::cover_summary(job, f);
  CHECK(summary.find("1 refused for collisions, not counted") != std::string::npos);
  CHECK(progress.back() == summary + " without the refused patches");
  CHECK(pipeline::cover_report(job, f)["patches_refused"] == 1);
  // detected-job.yaml marks it (a re-run would fit it again) and keeps the tool's end.
  const std::string detected = pipeline::detected_job_yaml(job, f);
  CHECK(detected.find("  # blade: refused for collisions (no program; see report.json)\n  - name: blade\n") != std::string::npos);
  CHECK(detected.find("end: {corner: 1}}") != std::string::npos);
}

TEST_CASE("flankcam run: a motion whose shank comes inside the clearance at its end is shortened to its clear poses and checked again" *
          doctest::test_suite("heavy")) {
  // The blade's patch fitted without a part. Then a block the fit never saw (the part the collision
  // check judges: the job's part without the blade's twin) 0.25 mm off the shank at the last poses:
  // the check finds the shank inside the 0.5 mm clearance there. The motion is shortened to its
  // longest clear stretch of poses (over three quarters of it), its coverage judged anew, and the
  // check of what is kept is clean.
  test::ScratchDir dir("clear-stretch");
  const std::string tool = "tool: {shape: cone}\nholder: {shank_length: 20, shank_diameter: 6, length: 30, diameter: 20}\n"
                           "clearance: 0.5\n";
  test::write_text(dir.file("job.yaml"), blade_job(tool));
  const pipeline::Job job = pipeline::read_job(dir.file("job.yaml"));
  const pipeline::FitRun plain = pipeline::fit(pipeline::read_job(dir.file("job.yaml")), {});
  pipeline::FittedJob f = plain.fitted;
  const pipeline::FittedPatch& p0 = plain.fitted.patches.at(0);
  REQUIRE(p0.collisions.clear());
  const size_t n = p0.poses.size();
  REQUIRE(n > 20);
  REQUIRE(0.5 * p0.assembly.shank_diameter == doctest::Approx(3));
  f.check_part = shank_block(p0, n - 1, 0.5, 3);
  std::vector<std::string> progress;
  const auto log = [&](const std::string& s) { progress.push_back(s); };
  pipeline::check_job(job, f, log);
  const pipeline::FittedPatch& p = f.patches.at(0);
  REQUIRE_FALSE(p.collisions.clear());
  for (const CollisionInterval& iv : p.collisions.intervals) {
    CHECK(iv.component == Component::Shank);
    CHECK(iv.max_depth_mm < 0);                      // inside the clearance, not into the shank
    CHECK(iv.max_depth_mm == doctest::Approx(-0.25).epsilon(0.2));
    CHECK(size_t(iv.pose_end) == n - 1);              // at the end of the motion only
    CHECK(size_t(iv.pose_begin) > n / 2);
  }
  const size_t first_hit = size_t(p.collisions.intervals.front().pose_begin);
  pipeline::shorten_to_clear(job, f, log);
  INFO(p.kept_clear);
  REQUIRE_FALSE(p.kept_clear.empty());
  CHECK(p.kept_clear.find("beyond them the shank would come") != std::string::npos);
  CHECK(p.kept_for_leads.empty());
  // Kept: every pose before the first colliding one, nothing after; checked again, clear.
  CHECK(p.poses.size() == first_hit);
  CHECK(p.poses.front().tip.isApprox(p0.poses.front().tip, 1e-12));
  CHECK(p.poses.back().tip.isApprox(p0.poses[first_hit - 1].tip, 1e-12));
  CHECK(p.collisions.clear());
  CHECK(p.collisions.positions_checked > 0);
  CHECK(p.fit.t_from == doctest::Approx(p0.fit.t_from));
  CHECK(p.fit.t_to < p0.fit.t_to);
  CHECK(p.fit.t_to == doctest::Approx(p0.fit.t_from + (p0.fit.t_to - p0.fit.t_from) * double(first_hit - 1) / double(n - 1)));
  // Judged anew: less covered than the whole motion, most of it kept.
  MESSAGE("coverage ", p0.fit.coverage, " -> ", p.fit.coverage, ", poses ", n, " -> ", p.poses.size());
  CHECK(p.fit.coverage < p0.fit.coverage);
  CHECK(p.fit.coverage > 0.5 * p0.fit.coverage);
  CHECK(std::any_of(progress.begin(), progress.end(), [](const std::string& s) { return s.find("kept (t ") != std::string::npos; }));
  // Shortened again (as the run does for a lead with no clear point): the kept poses lie evenly over
  // the trimmed rails, so dropping the last of them keeps t_to at that pose's t of the first motion,
  // and the rails' end at that pose (an end kept keeps its t exactly).
  {
    pipeline::FittedJob again = f;
    const size_t k = again.patches[0].poses.size();
    const ToolPose last_kept = again.patches[0].poses[k - 2];
    std::vector<std::optional<pipeline::KeptPoses>> keep{pipeline::KeptPoses{0, k - 2, "a lead"}};
    pipeline::keep_poses(job, again, keep, &pipeline::FittedPatch::kept_for_leads, "for their leads", log);
    const pipeline::FittedPatch& a = again.patches[0];
    CHECK(a.poses.size() == k - 1);
    CHECK(a.fit.t_from == p.fit.t_from);
    CHECK(a.fit.t_to == doctest::Approx(p0.fit.t_from + (p0.fit.t_to - p0.fit.t_from) * double(first_hit - 2) / double(n - 1)));
    const Eigen::Vector3d tip_end = again.frame.to_mm(a.fit.fit.rails.a.point(1));
    CHECK((tip_end - last_kept.tip).norm() < 1e-3);
  }
  // With an earlier pass 0.3 mm off: its poses are cut like the last pass's, its rails trimmed to the
  // same stretch (their end at its last kept pose) and its coverage judged anew.
  {
    test::write_text(dir.file("passes.yaml"), blade_job(tool + "passes: [{allowance: 0.3}, {allowance: 0}]\n"));
    const pipeline::Job pj = pipeline::read_job(dir.file("passes.yaml"));
    const pipeline::FitRun two = pipeline::fit(pipeline::read_job(dir.file("passes.yaml")), {});
    pipeline::FittedJob t = two.fitted;
    t.check_part = f.check_part;
    pipeline::check_job(pj, t, log);
    REQUIRE_FALSE(t.patches.at(0).collisions.clear());
    REQUIRE(t.patches[0].earlier_passes.size() == 1);
    const double pass_coverage = t.patches[0].earlier_passes[0].coverage;
    pipeline::shorten_to_clear(pj, t, log);
    const pipeline::FittedPatch& s2 = t.patches[0];
    REQUIRE_FALSE(s2.kept_clear.empty());
    CHECK(s2.collisions.clear());
    const pipeline::PassMotion& rough = s2.earlier_passes[0];
    CHECK(rough.poses.size() == s2.poses.size());
    CHECK(rough.contacts.size() == s2.poses.size());
    CHECK((t.frame.to_mm(rough.rails.a.point(1)) - rough.poses.back().tip).norm() < 1e-3);
    CHECK((t.frame.to_mm(rough.rails.a.point(0)) - rough.poses.front().tip).norm() < 1e-3);
    CHECK(rough.coverage < pass_coverage);
  }
  // A block beside the middle of the motion as well: no clear stretch of three quarters of the motion
  // is left, and the motion is refused whole, its collisions reported, as before.
  pipeline::FittedJob g = plain.fitted;
  g.check_part = test::merged(*f.check_part, shank_block(p0, n / 2, 0.3, 0.3));
  pipeline::check_job(job, g, log);
  REQUIRE(g.patches.at(0).collisions.intervals.size() >= 2);
  pipeline::shorten_to_clear(job, g, log);
  const pipeline::FittedPatch& q = g.patches.at(0);
  CHECK_FALSE(q.collisions.clear());
  CHECK(q.kept_clear.empty());
  CHECK(q.poses.size() == n);
  CHECK(q.fit.t_to == p0.fit.t_to);
  // The first block alone with the job's overtravel: the overtravel pose is the user's and would be
  // lost, so the motion is refused whole too.
  pipeline::Job over = job;
  over.overtravel_mm = 2;
  pipeline::FittedJob h = plain.fitted;
  h.check_part = f.check_part;
  pipeline::check_job(over, h, log);
  REQUIRE(h.patches.at(0).poses.size() == n + 2);
  REQUIRE_FALSE(h.patches.at(0).collisions.clear());
  pipeline::shorten_to_clear(over, h, log);
  CHECK_FALSE(h.patches.at(0).collisions.clear());
  CHECK(h.patches.at(0).kept_clear.empty());
  CHECK(h.patches.at(0).poses.size() == n + 2);
}
