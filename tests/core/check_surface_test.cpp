// Check surfaces in the fit (issue 15): the part keeps the tool out, by tilting where the design
// surface allows it and by trimming where nothing can; the part's twin of the design surface is
// left to the design surface itself.
#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "core/check_surface.h"
#include "core/collision.h"
#include "core/detect.h"
#include "core/fitting.h"
#include "core/patch.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// The flank x = 0 over y in [0, 60], z in [0, 20] (mm), normals +x (out of the material, x < 0).
TriMesh flank(int ny = 31, int nz = 11) {
  return test::grid_mesh(ny, nz, [&](int j, int k) { return Eigen::Vector3d(0, 60.0 * j / (ny - 1), 20.0 * k / (nz - 1)); });
}


TriMesh to_unit(TriMesh m, const Similarity& fr) { return transformed(m, fr); }

struct Setup {
  TriMesh phi_mm = flank();
  Similarity fr = unit_diagonal_frame(phi_mm);
  SurfaceIndex phi{transformed(phi_mm, fr)};
  FitOptions o;
  Rails initial;
  Setup() {
    o.shape = ToolShape::General;
    std::vector<AxisLine> lines;
    for (double y : {5.0, 20.0, 35.0, 50.0})  // vertical axis lines 5 mm off the flank, tip at z = 0
      lines.push_back({fr.to_unit({5, y, 0}), fr.to_unit({5, y, 20})});
    initial = rails_from_lines(lines, 0, 0, o);
  }
  // Shank Ø6 over 10 mm, then a holder Ø20 over 30 mm (mm, beyond the cutter's end).
  std::vector<Eigen::Vector2d> body() const {
    std::vector<Eigen::Vector2d> b;
    for (int k = 0; k <= 40; ++k) b.emplace_back(fr.length_to_unit(k), fr.length_to_unit(k <= 10 ? 3.0 : 10.0));
    return b;
  }
  // The patch of the upright lines (tip at z = 0) and its options: coverage within 0.01 mm.
  PatchSpec upright() const {
    PatchSpec spec;
    spec.name = "p";
    for (double y : {5.0, 20.0, 35.0, 50.0}) spec.lines.push_back({fr.to_unit({5, y, 0}), fr.to_unit({5, y, 20})});
    return spec;
  }
  PatchOptions patch_options() const {
    PatchOptions po;
    po.fit = o;
    po.tolerance = fr.length_to_unit(0.01);
    return po;
  }
  // The lowest z (mm) of the rails' a end (the tip) over 21 poses.
  double lowest_tip_z(const Rails& r) const {
    double z = INFINITY;
    for (int i = 0; i <= 20; ++i) z = std::min(z, fr.to_mm(r.a.point(i / 20.0)).z());
    return z;
  }
  // patch_options() over a hub: the cutter within 0.005 mm of it, the shank and holder of body().
  PatchOptions over_hub(const SurfaceIndex& hub) const {
    PatchOptions po = patch_options();
    po.fit.check.part = &hub;
    po.fit.check.tolerance = fr.length_to_unit(0.005);
    po.fit.check.body = body();
    return po;
  }
  // patch_options() against `part`: the cutter within 0.005 mm of it, shank and holder 1 mm off.
  PatchOptions checked_options(const SurfaceIndex& part) const {
    PatchOptions po = patch_options();
    po.fit.check.part = &part;
    po.fit.check.tolerance = fr.length_to_unit(0.005);
    po.fit.check.clearance = fr.length_to_unit(1.0);
    return po;
  }
  // How far the axis leans away from the wall (+x) at the holder end, mm: x of b minus x of a.
  double lean_mm(const Rails& r, double t) const {
    return fr.length_to_mm((r.b.point(t) - r.a.point(t)).x());
  }
};

// The fitted motion (tip at a) and its assembly in mm, checked as the job's collision check does:
// 101 poses, the cutter's spheres, a Ø6 shank of `shank_mm` and a Ø20 holder of 20 mm, clearance
// 1 mm, gouge tolerance 0.005 mm.
CollisionReport collisions_mm(const Setup& s, const PatchFit& f, const SurfaceIndex& part_mm, double shank_mm) {
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 100; ++i) {
    const Eigen::Vector3d a = s.fr.to_mm(f.fit.rails.a.point(i / 100.0)), b = s.fr.to_mm(f.fit.rails.b.point(i / 100.0));
    poses.push_back({a, (b - a).normalized()});
  }
  ToolAssembly t;
  const double L = s.fr.length_to_mm(f.fit.rails.length);
  for (int j = 0; j <= 100; ++j) t.cutter.emplace_back(L * j / 100, s.fr.length_to_mm(f.fit.tool.d(j / 100.0)));
  t.shank_length = shank_mm, t.shank_diameter = 6, t.holder_length = 20, t.holder_diameter = t.holder_diameter_far = 20;
  CollisionOptions co;
  co.clearance_mm = 1.0;
  co.gouge_tolerance_mm = 0.005;
  return check_collisions(part_mm, poses, t, co);
}
}  // namespace

TEST_CASE("a tool standing next to a wall tilts away instead of cutting it" * doctest::test_suite("heavy")) {
  Setup s;
  // The opposite wall at x >= 14 mm: the upright tool's holder (radius 10 about x = 5) reaches x = 15.
  const SurfaceIndex wall(to_unit(test::box_mesh({14, -20, -10}, {30, 80, 100}, 4), s.fr));
  // The tip keeps its Ø10 (a tool may not simply become thinner and move closer to the flank).
  s.o.constraints.min_tip_radius = s.fr.length_to_unit(4.9);
  s.o.constraints.max_cone_angle_rad = 15 * M_PI / 180;
  const FitResult free = optimize_motion(s.phi, s.initial, s.o);
  FitOptions o = s.o;
  o.check.part = &wall;
  o.check.tolerance = s.fr.length_to_unit(0.005);
  o.check.clearance = s.fr.length_to_unit(1.0);
  o.check.body = s.body();
  const FitResult fit = optimize_motion(s.phi, s.initial, o);
  // Without the wall the axis stays upright and the holder enters it (1 mm deep plus the clearance).
  const CheckProfile before = check_profile(free.rails, free.tool, o.check, 50, o.samples_s);
  CHECK(std::abs(s.lean_mm(free.rails, 0.5)) < 0.05);
  CHECK(s.fr.length_to_mm(*std::max_element(before.intrusion.begin(), before.intrusion.end())) > 1.9);
  // With it the axis leans away (the tool becomes a cone that still lies flat on the flank) and
  // shank and holder keep the clearance everywhere, while the flank is still cut within 0.005 mm.
  const CheckProfile after = check_profile(fit.rails, fit.tool, o.check, 50, o.samples_s);
  const double worst = s.fr.length_to_mm(*std::max_element(after.intrusion.begin(), after.intrusion.end()));
  MESSAGE("lean ", s.lean_mm(fit.rails, 0.5), " mm over the cutter, tip axis at x = ", s.fr.to_mm(fit.rails.a.point(0.5)).x(),
          " mm, worst intrusion ", worst, " mm, eps ",
          s.fr.length_to_mm(fit.eps_opt.max), " mm");
  CHECK(s.lean_mm(fit.rails, 0.5) < -1.0);
  CHECK(s.fr.to_mm(fit.rails.a.point(0.5)).x() > 4.85);
  CHECK(worst < 0.05);
  CHECK(s.fr.length_to_mm(fit.eps_opt.max) < 0.005);
  CHECK(fit.tool.d(1.0) < fit.tool.d(0.0));  // narrower at the holder end: a taper
}

TEST_CASE("a post in the cutter's way: the motion is kept clear of it or trimmed, and says why" * doctest::test_suite("heavy")) {
  Setup s;
  // A post at y >= 52 mm standing where the cutter (Ø10 about x = 5) would end its motion (y = 55).
  const SurfaceIndex post(to_unit(test::box_mesh({1, 52, -10}, {30, 80, 100}, 4), s.fr));
  PatchOptions po = s.patch_options();
  po.fit.check.part = &post;
  po.fit.check.tolerance = s.fr.length_to_unit(0.005);
  const PatchSpec spec = s.upright();
  const PatchFit f = fit_patch(s.phi, spec, po);
  // Kept clear: the cutter's worst intrusion is within the tolerance, and the last position's tool
  // ends before the post.
  MESSAGE("t ", f.t_from, "-", f.t_to, ", intrusion ", s.fr.length_to_mm(f.check_intrusion), " mm, coverage ", f.coverage);
  CHECK(f.check_intrusion <= 0);
  CHECK(!f.check_refused);
  const double y_end = s.fr.to_mm(f.fit.rails.a.point(1)).y() + s.fr.length_to_mm(f.fit.tool.d(0));
  CHECK(y_end < 52.0 + 0.005);
  // The flank up to the post (less the cutter's radius) is still cut: 38 of its 60 mm at least.
  CHECK(f.coverage > 38.0 / 60);
  // The patch's ε is that of the motion as kept (eq. 13 over the trimmed rails), not of the stretch
  // trimmed off, which is not machined.
  REQUIRE(f.t_to - f.t_from < 0.99);
  const ErrorStats kept = sample_error(s.phi, f.fit.rails, f.fit.tool, po.fit);
  MESSAGE("eps kept ", s.fr.length_to_mm(f.fit.eps_opt.max), " mm");
  CHECK(f.fit.eps_opt.max == kept.max);
  CHECK(f.fit.eps_opt.samples == kept.samples);
  // Without the post the motion ran on to y = 55, into it; the trimming (or the fit) says where it hit.
  PatchOptions free = po;
  free.fit.check = {};
  const PatchFit g = fit_patch(s.phi, spec, free);
  CHECK(s.fr.to_mm(g.fit.rails.a.point(1)).y() + s.fr.length_to_mm(g.fit.tool.d(0)) > 52.5);
}

TEST_CASE("the part's twin of the design surface is left out of the check surface, and a part is turned outward") {
  const TriMesh phi_mm = flank(31, 11);
  const SurfaceIndex phi(phi_mm);
  // The blade block behind the flank: its x = 0 side is the flank's twin (4 x 4 squares: 32 triangles).
  const TriMesh block = test::box_mesh({-10, 0, 0}, {0, 60, 20}, 4);
  const CheckPart cp = check_part(block, phi, 0.01);
  CHECK(cp.twin_faces == 32);
  CHECK(cp.mesh.faces.size() == block.faces.size() - 32);
  CHECK(!cp.turned_outward);
  for (size_t f = 0; f < cp.mesh.faces.size(); ++f) CHECK(face_normal(cp.mesh, int(f)).x() < 0.5);  // no +x face left
  // Inward faces (a closed part read with the other orientation) are turned outward.
  TriMesh inward = block;
  for (auto& f : inward.faces) std::swap(f[1], f[2]);
  const CheckPart turned = check_part(inward, phi, 0.01);
  CHECK(turned.turned_outward);
  CHECK(turned.twin_faces == 32);
  CHECK(signed_volume(merged(turned.mesh, phi_mm)) > 0);  // closed again by the flank: outward
  // A face near the flank but across it (the other side of a thin edge) is kept.
  const TriMesh thin = test::box_mesh({-0.005, 0, 0}, {0, 60, 20}, 4);
  CHECK(check_part(thin, phi, 0.01).twin_faces == 32);
}

TEST_CASE("a point just behind the design surface is as deep as it lies behind it, not as the blade is thick") {
  // A blade 6 mm thick behind the flank x = 0 (its twin in the part). A cutter sample 0.1 mm behind
  // Φ gouges it by 0.1 mm: its depth is 0.1, the way out back through Φ, not the 5.9 mm to the far
  // side of the blade (the part without the twin), as the HECC impeller's Ø6 fits were told.
  const TriMesh phi_mm = test::grid_mesh(31, 11, [](int j, int k) { return Eigen::Vector3d(0, 2.0 * j, 2.0 * k); });
  const TriMesh blade = test::box_mesh({-6, 0, 0}, {0, 60, 20}, 4);
  const SurfaceIndex phi(phi_mm);
  const CheckPart cp = check_part(blade, phi, 0.01);
  REQUIRE(cp.twin_faces == 32);
  const SurfaceIndex part(cp.mesh), solid(blade);
  CheckSurface c;
  c.part = &part, c.solid = &solid, c.solid_twin = &cp.twin, c.twin_sag = cp.twin_sag, c.tolerance = 0.01;
  const std::vector<double> d = cutter_clearances(c, {{-0.1, 30, 10}, {-2, 30, 10}, {-5, 30, 10}, {-0.005, 30, 10}, {1, 30, 10}});
  CHECK(d[0] == doctest::Approx(-0.1));  // behind Φ: through Φ
  CHECK(d[1] == doctest::Approx(-2));    // nearer Φ than the far side
  CHECK(d[2] == doctest::Approx(-1));    // nearer the far side: through it
  CHECK(d[3] > 0);                       // within the tolerance behind Φ: Φ's to judge, outside the part
  CHECK(d[4] == doctest::Approx(7));     // in front: the nearest face but the twin (the far side, through the hole)
}

namespace {
// Upright rails at x = `x` mm (y 10..50, the cutter's tip at z = 5, its holder end at z = 25) and a
// cylinder of radius `r` mm, in frame `fr`.
Rails upright_rails(const Similarity& fr, double x) {
  std::vector<AxisLine> lines;
  for (double y : {10.0, 25.0, 40.0, 50.0}) lines.push_back({fr.to_unit({x, y, 5}), fr.to_unit({x, y, 25})});
  return rails_from_lines(lines, 0, 0, FitOptions{});
}
ToolRadius cylinder_of(const Similarity& fr, double r) {
  ToolRadius cylinder;
  cylinder.shape = ToolShape::Cylinder;
  cylinder.D = {fr.length_to_unit(r)};
  return cylinder;
}
}  // namespace

TEST_CASE("shank and holder keep their clearance from the design surface too: a shank wider than the cutter over a taller flank") {
  // Φ: the flank x = 0, y in [0, 60], z in [0, 100]; the part: the block behind it, whose x = 0 side
  // is Φ's twin (left out of the check surface). The cutter (Ø10, z 5-25) runs along Φ, and above
  // it the shank (40 mm) along Φ's continuation, as on a blade taller than the tool (rotor 37).
  const TriMesh phi_mm = test::grid_mesh(31, 51, [](int j, int k) { return Eigen::Vector3d(0, 2.0 * j, 2.0 * k); });
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  const TriMesh block = transformed(test::box_mesh({-10, 0, 0}, {0, 60, 100}, 4), fr);
  const CheckPart cp = check_part(block, phi, fr.length_to_unit(0.01));
  REQUIRE(cp.twin_faces == 32);
  const SurfaceIndex part(cp.mesh), solid(block);
  const Rails rails = upright_rails(fr, 5);
  const ToolRadius cylinder = cylinder_of(fr, 5);
  // The worst intrusion (mm) over the motion with a shank of radius r (clearance 1 mm), and whether
  // it is the body's.
  const auto worst = [&](double r) {
    CheckSurface c;
    c.part = &part, c.solid = &solid, c.solid_twin = &cp.twin, c.twin_sag = cp.twin_sag;
    c.tolerance = fr.length_to_unit(0.01), c.clearance = fr.length_to_unit(1.0);
    c.up = Eigen::Vector3d::UnitZ();
    for (int k = 0; k <= 40; ++k) c.body.emplace_back(fr.length_to_unit(k), fr.length_to_unit(r));
    const CheckProfile p = check_profile(rails, cylinder, c, 50, 30, true);
    const auto w = std::max_element(p.intrusion.begin(), p.intrusion.end());
    return std::make_pair(fr.length_to_mm(*w), p.body[size_t(w - p.intrusion.begin())] != 0);
  };
  // Ø12: 1 mm into Φ above the cut, plus the clearance (the samples grown to enclose their slabs: a
  // little more). Before, the shank was measured against the part without the twin: clear.
  const auto [into, into_body] = worst(6.0);
  CHECK(into_body);
  CHECK(into == doctest::Approx(2.0).epsilon(0.08));
  // Ø9: 0.5 mm off Φ, inside the 1 mm clearance by 0.5.
  const auto [near, near_body] = worst(4.5);
  CHECK(near_body);
  CHECK(near == doctest::Approx(0.5).epsilon(0.3));
  // Ø7: 1.5 mm off Φ: clear.
  CHECK(worst(3.5).first <= 0);
}

namespace {
// The flank x = 0 (y 0-60, z 0-24.7 mm) in front of its block, the part's twin of it left out, in the
// unit frame `fr`; check(r) is its check surface for a shank of radius r mm from the cutter's end
// (30 mm, samples every 2 mm), tolerance 0.01 mm, clearance 1 mm, up +z.
struct FlankBeforeBlock {
  TriMesh phi_mm = test::grid_mesh(13, 31, [](int j, int k) { return Eigen::Vector3d(0, 2.0 * k, 24.7 * j / 12); });
  Similarity fr = unit_diagonal_frame(phi_mm);
  SurfaceIndex phi{transformed(phi_mm, fr)};
  TriMesh block = transformed(test::box_mesh({-10, 0, 0}, {0, 60, 24.7}, 4), fr);
  CheckPart cp = check_part(block, phi, fr.length_to_unit(0.01));
  SurfaceIndex part{cp.mesh}, solid{block};
  CheckSurface check(double shank_radius_mm) const {
    CheckSurface c;
    c.part = &part, c.solid = &solid, c.solid_twin = &cp.twin, c.twin_sag = cp.twin_sag;
    c.tolerance = fr.length_to_unit(0.01), c.clearance = fr.length_to_unit(1.0);
    c.up = Eigen::Vector3d::UnitZ();
    for (int k = 0; k <= 30; k += 2) c.body.emplace_back(fr.length_to_unit(k), fr.length_to_unit(shank_radius_mm));
    return c;
  }
};
}  // namespace

TEST_CASE("a shank wider than the cutter passing just above the flank's edge is seen at its rim") {
  // The flank x = 0 (z 0-24.7 mm) in front of its block, the part's twin of it left out. The Ø6
  // cutter (axis x = 3, z 5-25) ends 0.3 mm above the flank's top edge; its Ø8 shank starts there,
  // reaching 1 mm over the block: 0.3 mm above its top face, 0.7 mm inside the 1 mm clearance (the
  // HECC diffuser's vane under a detected patch's shank). The part points nearest to the shank's
  // axis lie on the flank the cutter touches, 1.04 mm from the shank's rim: without samples on the
  // rim this was judged clear, and the collision check refused the program.
  const FlankBeforeBlock f;
  REQUIRE(f.cp.twin_faces > 0);
  const Similarity& fr = f.fr;
  const Rails rails = upright_rails(fr, 3);
  const ToolRadius cylinder = cylinder_of(fr, 3);
  const CheckSurface c = f.check(4);
  for (const bool enclose : {false, true}) {
    const CheckProfile p = check_profile(rails, cylinder, c, 50, 30, enclose);
    const auto w = std::max_element(p.intrusion.begin(), p.intrusion.end());
    CHECK(p.body[size_t(w - p.intrusion.begin())] != 0);
    CHECK(fr.length_to_mm(*w) == doctest::Approx(0.7).epsilon(0.03));
    // All along the motion, not at one row.
    CHECK(std::count_if(p.intrusion.begin(), p.intrusion.end(), [&](double v) { return fr.length_to_mm(v) > 0.65; }) == 50);
  }
}

// The same flank and block under a Ø10 cutter (axis x = 5) whose end is 0.3 mm above the flank's top
// edge, with a Ø9 shank: the edge is 0.58 mm from the shank's rim, inside the 1 mm clearance, but
// under the cutter's end face, which the shank cannot pass: the cutter's alone (NASA rotor 37: a Ø8
// shank over a Ø9.7 cutter skimming the blade's tip face was held off it, and its patches trimmed).
// Without the tolerance on the cutter's radius, the edge where the cutter touches the flank counted:
// 0.53 mm of shank intrusion on 30 of the 50 rows.
TEST_CASE("a shank narrower than the cutter is not held off the part under the cutter's end face") {
  const FlankBeforeBlock f;
  const Similarity& fr = f.fr;
  CheckSurface c = f.check(4.5);
  for (const bool enclose : {false, true}) {
    CAPTURE(enclose);
    const CheckProfile p = check_profile(upright_rails(fr, 5), cylinder_of(fr, 5), c, 50, 30, enclose);
    CHECK(fr.length_to_mm(*std::max_element(p.intrusion.begin(), p.intrusion.end())) < 0.005);
    CHECK(std::count(p.body.begin(), p.body.end(), char(0)) == 50);
  }
  // The shank's rim 0.1 mm wider than the cutter (Ø10.2): the edge is under the shank's end face, 0.3 mm
  // below it, and the shank is held off it again.
  for (Eigen::Vector2d& b : c.body) b.y() = fr.length_to_unit(5.1);
  const CheckProfile wide = check_profile(upright_rails(fr, 5), cylinder_of(fr, 5), c, 50, 30, true);
  const auto w = std::max_element(wide.intrusion.begin(), wide.intrusion.end());
  CHECK(wide.body[size_t(w - wide.intrusion.begin())] != 0);
  CHECK(fr.length_to_mm(*w) > 0.6);
}

namespace {
// The worst intrusion (mm) of the upright motion's Ø10 cylinder, Ø6 shank z 20-40 and Ø20 holder
// z 40-70 (the body as the job gives it, both sides of the step at u = 20 mm; samples every 2 mm,
// clearance 1 mm) into `part_mm`, coarse and grown profiles alike, where shank or holder is worst.
double worst_body_intrusion(const Setup& s, const TriMesh& part_mm) {
  ToolRadius cylinder;
  cylinder.shape = ToolShape::Cylinder;
  cylinder.D = {s.fr.length_to_unit(5)};
  const SurfaceIndex part(to_unit(part_mm, s.fr));
  CheckSurface c;
  c.part = &part;
  c.tolerance = s.fr.length_to_unit(0.005), c.clearance = s.fr.length_to_unit(1.0);
  c.up = Eigen::Vector3d::UnitZ();
  for (int k = 0; k <= 20; k += 2) c.body.emplace_back(s.fr.length_to_unit(k), s.fr.length_to_unit(3));
  for (int k = 20; k <= 50; k += 2) c.body.emplace_back(s.fr.length_to_unit(k), s.fr.length_to_unit(10));
  double out = -INFINITY;
  for (const bool enclose : {false, true}) {
    const CheckProfile p = check_profile(s.initial, cylinder, c, 50, 30, enclose);
    const auto w = std::max_element(p.intrusion.begin(), p.intrusion.end());
    CHECK(p.body[size_t(w - p.intrusion.begin())] != 0);
    out = std::max(out, s.fr.length_to_mm(*w));
  }
  return out;
}
// The clearance is kept with the sag of the spacing of the sample that found the point in hand:
// hypot(1, 3) - 3 = 0.162 mm on the shank, hypot(1, 10) - 10 = 0.050 on the holder (every 2 mm).
const double shank_bulge = std::hypot(1.0, 3.0) - 3, holder_bulge = std::hypot(1.0, 10.0) - 10;
}  // namespace

TEST_CASE("a holder wider than its shank is judged by its face, not by balls that bulge below it") {
  // A ledge at x >= 12 (7 mm off the axis x = 5: under the holder's rim, 4 mm clear of the shank),
  // from z = 25 (clear of the cutter) to `top` mm below the holder's face.
  Setup s;
  const auto worst = [&](double top) { return worst_body_intrusion(s, test::box_mesh({12, -20, 25}, {40, 80, 40 - top}, 4)); };
  // 4 mm below the face: clear by 4 mm of both shank and face, 3 mm beyond the clearance (a ball of
  // the holder's radius at its face reached 10 mm below it: 2.9 mm "inside" the clearance; the old
  // trim view grew the shank's last ball so).
  CHECK(worst(4.0) == doctest::Approx(-3.0 + shank_bulge).epsilon(0.01));
  // 0.4 mm below the face: 0.6 mm inside the 1 mm clearance, seen by the face (the shank's last
  // sample finds the ledge's edge).
  CHECK(worst(0.4) == doctest::Approx(0.6 + shank_bulge).epsilon(0.01));
  // Up to 5 mm above the face: 3 mm into the holder's side (7 mm off the axis, radius 10), 4 mm
  // inside the clearance.
  CHECK(worst(-5.0) == doctest::Approx(4.0 + holder_bulge).epsilon(0.01));
}

TEST_CASE("a rail entering the holder through its face is seen behind a nearer clear ledge beside the shank") {
  // A ledge 2.5 mm beside the Ø6 shank (x >= 10.5), its top 2 mm under the holder's face, and a wall
  // 2 mm beside the holder (x >= 17, z 45-80): clear. On the other side a rail 9.5-9.9 mm off the
  // axis (inside the Ø20 holder's radius) rising 0.5 mm through the face. Ledge and wall are nearer
  // than the rail to every axis point, so one nearest part point per sample misses the rail (the
  // old code: -0.84 mm, clear); the slab's own nearest point (closest_in_slab) finds it.
  Setup s;
  const TriMesh ledge = test::merged(test::box_mesh({10.5, -20, 25}, {40, 80, 38}, 4), test::box_mesh({17, -20, 45}, {40, 80, 80}, 4));
  // Ledge and wall alone: the ledge 2 mm under the face (2.5 mm off the shank), 1 mm beyond the clearance.
  CHECK(worst_body_intrusion(s, ledge) == doctest::Approx(-1.0 + shank_bulge).epsilon(0.01));
  // With the rail: 0.5 mm into the holder through its face and its side, 1.5 mm inside the clearance.
  CHECK(worst_body_intrusion(s, test::merged(ledge, test::box_mesh({-4.9, -20, 25}, {-4.5, 80, 40.5}, 4))) ==
        doctest::Approx(1.5 + holder_bulge).epsilon(0.01));
}

TEST_CASE("a shank passing the flank's edge inside the clearance: the cutter is made longer at its holder end" * doctest::test_suite("heavy")) {
  // The blade block behind the flank x = 0 ends at z = 20, where the upright cutter (Ø10, tip at
  // z = 0) ends too; its Ø9.4 shank starts there, 0.3 mm off the block's top edge: inside the 1 mm
  // clearance all along the motion (the HECC diffuser's shroud side: every patch trimmed for 0.12 mm).
  // Trimming cannot help; a cutter 1-2 mm longer starts the shank above the edge (> 1 mm off it).
  Setup s;
  const TriMesh block = to_unit(test::box_mesh({-10, 0, 0}, {0, 60, 20}, 4), s.fr);
  const CheckPart cp = check_part(block, s.phi, s.fr.length_to_unit(0.01));
  REQUIRE(cp.twin_faces == 32);
  const SurfaceIndex part(cp.mesh), solid(block);
  PatchOptions po = s.checked_options(part);
  po.fit.check.solid = &solid, po.fit.check.solid_twin = &cp.twin, po.fit.check.twin_sag = cp.twin_sag;
  po.fit.check.body.clear();
  for (int k = 0; k <= 40; ++k) po.fit.check.body.emplace_back(s.fr.length_to_unit(k), s.fr.length_to_unit(k <= 10 ? 4.7 : 10.0));
  const PatchFit f = fit_patch(s.phi, s.upright(), po);
  const double longer = s.fr.length_to_mm(f.holder_lengthened);
  MESSAGE("lengthened ", longer, " mm, t ", f.t_from, "-", f.t_to, ", intrusion ", s.fr.length_to_mm(f.check_intrusion),
          " mm, coverage ", f.coverage);
  CHECK(longer >= 0.9);
  CHECK(longer <= 8.1);
  CHECK(f.check_intrusion <= 0);
  CHECK(!f.check_refused);
  CHECK(f.t_to - f.t_from > 0.99);  // the whole motion kept
  // As much of the flank as the same patch without the part.
  const PatchFit free = fit_patch(s.phi, s.upright(), s.patch_options());
  CHECK(f.coverage >= 0.99 * free.coverage);
  // The shank starts above the block's top: the cutter's holder end (b) beyond z = 20 by the length added.
  for (double t : {0.0, 0.5, 1.0}) CHECK(s.fr.to_mm(f.fit.rails.b.point(t)).z() == doctest::Approx(20 + longer).epsilon(0.01));
}

TEST_CASE("check surface options name the bad field") {
  const SurfaceIndex wall(test::box_mesh({14, -20, -10}, {30, 80, 100}));
  FitOptions o;
  o.check.part = &wall;
  CHECK(o.validate().empty());
  o.check.weight = 0;
  CHECK(o.validate().find("check.weight") != std::string::npos);
  o.check.weight = 3;
  o.check.depth_limit = 1.5;
  CHECK(o.validate().find("check.depth_limit") != std::string::npos);
  o.check.depth_limit = 0.5;
  o.check.clearance = -1;
  CHECK(o.validate().find("clearance") != std::string::npos);
  o.check.clearance = 1;
  o.check.body = {{1.0, std::nan("")}};
  CHECK(o.validate().find("check.body") != std::string::npos);
}

namespace {
// The hub under the flank: a block below z = 0 whose top rises away from the flank, z = slope x
// (mm), so a flat tool end level with the flank's lower edge enters it (10 slope mm deep at x = 10).
TriMesh sloping_hub(double slope = 0.3) {
  TriMesh hub = test::box_mesh({0, -20, -10}, {30, 80, 0}, 4);
  for (Eigen::Vector3d& p : hub.vertices)
    if (p.z() > -1e-9) p.z() = slope * p.x();
  return hub;
}
}  // namespace

TEST_CASE("a tool whose end would cut the hub under the flank is ground shorter at its tip" * doctest::test_suite("heavy")) {
  Setup s;
  // The hub rises to 2.7 mm at x = 10: between two of the 5% (1 mm) steps of the 20 mm tool.
  const SurfaceIndex hub(to_unit(sloping_hub(0.27), s.fr));
  const PatchSpec spec = s.upright();
  const PatchFit free = fit_patch(s.phi, spec, s.patch_options());
  const PatchOptions po = s.over_hub(hub);
  // Without the hub the flat end sits level with the flank's lower edge, 2.7 mm into the hub at
  // x = 10 (less where the 12-point rim samples it).
  const CheckProfile before = check_profile(free.fit.rails, free.fit.tool, po.fit.check, 50, po.fit.samples_s);
  CHECK(s.fr.length_to_mm(*std::max_element(before.intrusion.begin(), before.intrusion.end())) > 2.5);
  const PatchFit f = fit_patch(s.phi, spec, po);
  // With it the cutter is shortened at its tip until its end just clears the hub (the 5% steps
  // refined by bisection: 2.7 mm, not the 3 mm of the next step): the whole motion is kept, nothing
  // enters the hub, and the flank above the cut is machined as before (what stays of the tool sweeps
  // the same surface).
  const double tip_z = s.lowest_tip_z(f.fit.rails);
  MESSAGE("tip at z = ", tip_z, " mm, length ", s.fr.length_to_mm(f.fit.rails.length), " mm (was ",
          s.fr.length_to_mm(free.fit.rails.length), "), coverage ", f.coverage, " (was ", free.coverage, "), eps ",
          s.fr.length_to_mm(f.fit.eps_opt.max), " mm");
  CHECK(f.check_intrusion <= 0);
  CHECK(!f.check_refused);
  CHECK(f.t_from == 0.0);
  CHECK(f.t_to == 1.0);
  CHECK(tip_z > 2.69);
  CHECK(tip_z < 2.8);
  CHECK(f.tip_shortened == doctest::Approx(free.fit.rails.length - f.fit.rails.length));
  CHECK(s.fr.length_to_mm(f.fit.eps_opt.max) < 0.01);
  // The band under the cut (2.7 of the flank's 20 mm; its rows lie at whole mm) is what is lost.
  CHECK(f.coverage > 0.84 * free.coverage);
  CHECK(f.coverage < 0.9 * free.coverage);
}

TEST_CASE("the holder end is chosen by the part: away from the hub whichever way up points") {
  Setup s;
  const SurfaceIndex hub(to_unit(sloping_hub(), s.fr));
  const FitResult fit = optimize_motion(s.phi, s.initial, s.o);  // tip (a) at z = 0, b at z = 20
  CheckSurface c;
  c.part = &hub;
  c.tolerance = s.fr.length_to_unit(0.005);
  c.body = s.body();
  const Eigen::Vector3d down = -Eigen::Vector3d::UnitZ(), across = Eigen::Vector3d::UnitY();
  // Holder at a would stand in the hub: b (+z) wins over a fallback pointing down or sideways.
  CHECK(holder_up(fit.rails, fit.tool, c, 50, down).z() > 0);
  CHECK(holder_up(fit.rails, fit.tool, c, 50, across).z() > 0);
  // Without a body to place (or without a part) the fallback decides.
  c.body.clear();
  CHECK(holder_up(fit.rails, fit.tool, c, 50, down).z() < 0);
  c.body = s.body();
  c.part = nullptr;
  CHECK(holder_up(fit.rails, fit.tool, c, 50, down).z() < 0);
}

TEST_CASE("cut_tool keeps the swept tool: rails and radii of the part that stays") {
  Setup s;
  for (const ToolShape shape : {ToolShape::Cone, ToolShape::General}) {
    FitOptions o = s.o;
    o.shape = shape;
    const FitResult fit = optimize_motion(s.phi, s.initial, o);
    ToolRadius tool = fit.tool;
    // A tool that is neither constant nor linear (the cone gets its own two values).
    if (shape == ToolShape::General)
      for (size_t k = 0; k < tool.D.size(); ++k) tool.D[k] = 0.02 + 0.004 * std::sin(0.5 * double(k));
    else
      tool.D = {0.02, 0.03};
    const double lo = 0.2, hi = 0.9;
    const ToolCut cut = cut_tool(fit.rails, tool, lo, hi);
    CHECK(cut.rails.length == doctest::Approx(fit.rails.length * (hi - lo)));
    double worst_axis = 0, worst_radius = 0;
    for (int i = 0; i <= 10; ++i)
      for (int j = 0; j <= 10; ++j) {
        const double t = i / 10.0, u = j / 10.0, sv = lo + (hi - lo) * u;
        worst_axis = std::max(worst_axis, (cut.rails.point(t, u) - fit.rails.point(t, sv)).norm());
        worst_radius = std::max(worst_radius, std::abs(cut.tool.d(u) - tool.d(sv)));
      }
    MESSAGE(std::string(to_string(shape)), ": axis ", worst_axis, ", radius ", worst_radius, " (reported ", cut.radius_error, ")");
    CHECK(worst_axis < 1e-12);
    if (shape == ToolShape::Cone) CHECK(worst_radius < 1e-15);
    // General: a least-squares spline over the shorter axis, within a thousandth of the waviness.
    CHECK(worst_radius < 1e-3 * 0.004);
    CHECK(worst_radius <= cut.radius_error * 1.01 + 1e-15);
  }
}

TEST_CASE("lengthened_at_tip continues the axis and the meridian's slope beyond the tip, and keeps the tool above it") {
  Setup s;
  for (const ToolShape shape : {ToolShape::Cone, ToolShape::General}) {
    FitOptions o = s.o;
    o.shape = shape;
    PatchFit base;
    base.fit = optimize_motion(s.phi, s.initial, o);  // tip (a) at z = 0
    // A tool widening linearly from its tip (a general tool's Greville values of a line are the line).
    ToolRadius& tool = base.fit.tool;
    const int K = int(tool.D.size());
    if (shape == ToolShape::General)
      for (int k = 0; k < K; ++k) {
        const double g = (std::clamp(k - 2, 0, K - 3) + std::clamp(k - 1, 0, K - 3) + std::clamp(k, 0, K - 3)) / (3.0 * (K - 3));
        tool.D[size_t(k)] = 0.02 + 0.01 * g;
      }
    else
      tool.D = {0.02, 0.03};
    PatchOptions po;
    po.fit = o;
    po.tolerance = s.fr.length_to_unit(0.01);
    const double L = base.fit.rails.length, e = 0.2 * L, f = e / L;
    const std::optional<PatchFit> l = lengthened_at_tip(base, po, e);
    REQUIRE(l.has_value());
    CHECK(l->fit.rails.length == doctest::Approx(1.2 * L));
    double worst_axis = 0, worst_radius = 0;
    for (int i = 0; i <= 10; ++i)
      for (int j = 0; j <= 12; ++j) {
        const double t = i / 10.0, u = j / 12.0, sv = -f + (1 + f) * u;  // s on the old tool
        worst_axis = std::max(worst_axis, (l->fit.rails.point(t, u) - base.fit.rails.point(t, sv)).norm());
        const double expected = sv < 0 ? 0.02 + 0.01 * sv : tool.d(sv);  // the slope at the tip continued
        worst_radius = std::max(worst_radius, std::abs(l->fit.tool.d(u) - expected));
      }
    MESSAGE(std::string(to_string(shape)), ": axis ", worst_axis, ", radius ", worst_radius, ", tip radius ", l->fit.tool.d(0));
    CHECK(worst_axis < 1e-12);
    CHECK(worst_radius < (shape == ToolShape::Cone ? 1e-15 : 1e-5));
    CHECK(l->fit.tool.d(0) == doctest::Approx(0.02 - 0.01 * f).epsilon(1e-4));
    CHECK(l->tip_lengthened == doctest::Approx(e));
    CHECK(l->tip_shortened == 0.0);
    // Lengthened so far that the continued meridian would end below zero: no tool.
    CHECK_FALSE(lengthened_at_tip(base, po, 2.5 * L).has_value());
    // A fixed tool is not ground.
    po.fit.fixed_tool = tool;
    CHECK_FALSE(lengthened_at_tip(base, po, e).has_value());
  }
}

TEST_CASE("a cutter stopping inside the flank, made longer at its end, reaches the flank's edge, the axis and radius going on") {
  // Lines from z = 0 to 12 mm on the 20 mm flank: the fitted cutter leaves the flank above z = 12 to
  // no motion. Made 8 mm longer at b, the same motion machines the flank to its top edge; beyond a,
  // the meridian goes on along its slope (a cylinder: the same radius).
  Setup s;
  PatchSpec spec = s.upright();
  for (AxisLine& l : spec.lines) l.b = s.fr.to_unit({5, s.fr.to_mm(l.b).y(), 12});
  PatchOptions po = s.patch_options();
  po.fit.constraints.max_length = s.fr.length_to_unit(25);
  const PatchFit base = fit_patch(s.phi, spec, po);
  const double e = s.fr.length_to_unit(8);
  const std::optional<PatchFit> longer = lengthened_to_reach(base, po, e, true);
  REQUIRE(longer.has_value());
  const PatchFit m = machine_and_trim(s.phi, *longer, po);
  double worst_axis = 0, worst_radius = 0;
  const double L = base.fit.rails.length, f = e / L;
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 12; ++j) {
      const double t = i / 10.0, u = j / 12.0, sv = (1 + f) * u;  // s on the old tool
      worst_axis = std::max(worst_axis, (longer->fit.rails.point(t, u) - base.fit.rails.point(t, sv)).norm());
      worst_radius = std::max(worst_radius, std::abs(longer->fit.tool.d(u) - base.fit.tool.d(std::min(sv, 1.0))));
    }
  MESSAGE("coverage ", base.coverage, " -> ", m.coverage, ", axis ", worst_axis, ", radius ", s.fr.length_to_mm(worst_radius),
          " mm, length ", s.fr.length_to_mm(L), " -> ", s.fr.length_to_mm(m.fit.rails.length), " mm");
  // The motion runs over y 5..50 mm, 75% of the flank: 0.75 x 12 / 20 of it before, its full height now.
  CHECK(base.coverage < 0.5);
  CHECK(m.coverage >= 0.9 * 0.75);
  CHECK(machinable(m));
  CHECK(worst_axis < 1e-12);
  CHECK(s.fr.length_to_mm(worst_radius) < 0.001);  // within a tenth of the tolerance (admissible_cut)
  CHECK(m.fit.rails.length == doctest::Approx(L + e));
  CHECK(m.reach_lengthened == doctest::Approx(e));
  // At a: the tip end goes on below z = 0, off the flank, and brings nothing.
  const std::optional<PatchFit> below = lengthened_to_reach(base, po, e, false);
  REQUIRE(below.has_value());
  CHECK(s.lowest_tip_z(below->fit.rails) == doctest::Approx(s.lowest_tip_z(base.fit.rails) - 8).epsilon(1e-6));
  // Beyond max_length (12 + 14 > 25 mm), or a fixed tool: none.
  CHECK_FALSE(lengthened_to_reach(base, po, s.fr.length_to_unit(14), true).has_value());
  po.fit.fixed_tool = base.fit.tool;
  CHECK_FALSE(lengthened_to_reach(base, po, e, true).has_value());
}

TEST_CASE("detection's last pass makes a cutter stopping inside the flank longer where the union grows, and only there") {
  // A cover of one patch whose 12 mm cutter stops inside the 20 mm flank over a floor 3 mm under its
  // tip: the pass tries it 1.2, 3, 6 and 13 mm longer (10%, 25%, 50% and to max_length 25 mm) and
  // keeps the one that machines most of what no other patch covers. Beside a patch as tall as the
  // flank that machines the same strip already, the union cannot grow: nothing is replaced.
  Setup s;
  const SurfaceIndex floor(to_unit(test::box_mesh({0, -20, -10}, {30, 80, -3}, 4), s.fr));
  PatchOptions po = s.over_hub(floor);
  po.fit.constraints.max_length = s.fr.length_to_unit(25);
  PatchSpec short_lines = s.upright();
  for (AxisLine& l : short_lines.lines) l.b = s.fr.to_unit({5, s.fr.to_mm(l.b).y(), 12});
  const PatchFit low = fit_patch(s.phi, short_lines, po), tall = fit_patch(s.phi, s.upright(), po);
  REQUIRE(machinable(low));
  REQUIRE(machinable(tall));
  CoverOptions co;
  co.patch = po;
  co.continue_ends = false;  // the motion continued past its ends: a test of its own (below)
  std::vector<PatchFit> alone{low};
  std::vector<size_t> seen;
  const std::vector<size_t> replaced = finish_cover(s.phi, alone, co, [&](size_t k, double) { seen.push_back(k); });
  MESSAGE("coverage ", low.coverage, " -> ", alone[0].coverage, ", made ", s.fr.length_to_mm(alone[0].reach_lengthened),
          " mm longer; the tall patch: ", tall.coverage);
  CHECK(seen == std::vector<size_t>{0});
  CHECK(replaced == std::vector<size_t>{0});
  CHECK(low.coverage < 0.5);
  CHECK(alone[0].coverage >= 0.9 * 0.75);  // the motion's 75% of the flank, to its top edge
  CHECK(s.fr.length_to_mm(alone[0].reach_lengthened) == doctest::Approx(13).epsilon(1e-6));
  CHECK(s.fr.length_to_mm(alone[0].fit.rails.length) <= 25 + 1e-6);
  CHECK(machinable(alone[0]));
  CHECK(s.lowest_tip_z(alone[0].fit.rails) == doctest::Approx(s.lowest_tip_z(low.fit.rails)).epsilon(1e-9));
  // The tall patch machines the strip above 12 mm already.
  std::vector<PatchFit> beside{low, tall};
  CHECK(finish_cover(s.phi, beside, co).empty());
  CHECK(beside[0].reach_lengthened == 0.0);
  CHECK(beside[0].fit.rails.length == low.fit.rails.length);
  // Without a part, or with a shared tool: no pass.
  std::vector<PatchFit> again{low};
  co.shared_tool = true;
  CHECK(finish_cover(s.phi, again, co).empty());
  co.shared_tool = false;
  co.patch = s.patch_options();
  CHECK(finish_cover(s.phi, again, co).empty());
  CHECK(again[0].reach_lengthened == 0.0);
}

TEST_CASE("a motion continued and anchored keeps its stretch as it was and takes the refit only past its ends") {
  // A bent motion (16 control points a rail, 40 mm long) and `further`: that motion continued by 20%
  // past both ends, then moved 0.5 mm sideways as a refit with the tool held may move it all.
  const auto rail = [](double dz) {
    Eigen::MatrixXd P(200, 3);
    std::vector<double> ts(200);
    for (int i = 0; i < 200; ++i) {
      const double t = i / 199.0;
      ts[size_t(i)] = t;
      P.row(i) << 5 * std::sin(2 * t), 40 * t, dz;
    }
    return fit_bspline(P, ts, 16);
  };
  const Rails original{rail(0), rail(20), 20};
  Rails further = continued(original, 0.2, 0.2);
  for (BSpline* c : {&further.a, &further.b})
    for (int i = 0; i < c->ctrl.rows(); ++i) c->ctrl(i, 0) += 0.5;
  const Rails r = anchored(original, further, 0.2, 0.2, 0.05);
  CHECK(r.a.ctrl.rows() == 16);
  CHECK(r.length == original.length);
  const auto at = [](const Rails& x, double u) { return x.a.point(u); };
  // The worst distance to the original over [0.3, 0.7] and to `further` beyond the ends. The spline
  // (16 control points over 1.4 of the first t) rings where the blend bends: 0.05 mm of the 0.5 at
  // t 0.15, 0.026 mm at 0.2, 0.014 mm over [0.3, 0.7] (under 3% of how far the refit moved, and a
  // refit with the tool held moves a motion by microns).
  double kept = 0, past = 0;
  for (int k = 0; k <= 140; ++k) {
    const double t = -0.2 + 0.01 * k, u = (t + 0.2) / 1.4;
    if (t >= 0.3 && t <= 0.7) kept = std::max(kept, (at(r, u) - at(original, t)).norm());
    if (t <= -0.05 || t >= 1.05) past = std::max(past, (at(r, u) - at(further, u)).norm());
  }
  MESSAGE("within the stretch ", kept, " mm from the motion as it was; past its ends ", past, " mm from the refit (moved 0.5 mm)");
  CHECK(kept <= 0.02);
  CHECK(past <= 0.06);
  // Continued at one end only, the other end is the motion's own.
  const Rails one = anchored(original, continued(original, 0, 0.2), 0, 0.2, 0.05);
  CHECK((one.a.point(0) - original.a.point(0)).norm() <= 1e-3);
}

TEST_CASE("detection's last pass continues a patch's motion past its ends where the union grows, judged against the part") {
  // A cover of one patch whose motion runs over y 5..50 mm of the 60 mm flank (upright lines, the
  // tip over a floor 3 mm under it). The last pass continues the motion past both ends by steps of 5%
  // of it (at most 40% an end; an end beyond Φ is not continued further), fits it again with its tool
  // held and judges it against the part: it machines the flank's width. A patch beside it that
  // machines those ends already leaves nothing to gain: nothing is replaced.
  Setup s;
  const SurfaceIndex floor(to_unit(test::box_mesh({0, -20, -10}, {30, 80, -3}, 4), s.fr));
  const PatchOptions po = s.over_hub(floor);
  const PatchFit mid = fit_patch(s.phi, s.upright(), po);
  REQUIRE(machinable(mid));
  const auto reach_y = [&](const PatchFit& f) {
    double lo = INFINITY, hi = -INFINITY;
    for (size_t v = 0; v < s.phi_mm.vertices.size(); ++v)
      if (std::isfinite(f.machined.design_deviation[v]) && std::abs(f.machined.design_deviation[v]) <= po.tolerance)
        lo = std::min(lo, s.phi_mm.vertices[v].y()), hi = std::max(hi, s.phi_mm.vertices[v].y());
    return std::pair{lo, hi};
  };
  CoverOptions co;
  co.patch = po;
  co.reach_further = false;
  std::vector<PatchFit> cover{mid};
  const std::vector<size_t> replaced = finish_cover(s.phi, cover, co);
  const PatchFit& c = cover[0];
  MESSAGE("coverage ", mid.coverage, " -> ", c.coverage, ", y ", reach_y(mid).first, "..", reach_y(mid).second, " -> ",
          reach_y(c).first, "..", reach_y(c).second, " mm, t ", c.t_from, "..", c.t_to, ", tip z ", s.lowest_tip_z(mid.fit.rails),
          " -> ", s.lowest_tip_z(c.fit.rails), " mm");
  CHECK(reach_y(mid).first >= 4);
  CHECK(reach_y(mid).second <= 51);
  REQUIRE(replaced == std::vector<size_t>{0});
  CHECK(c.t_from < 0);
  CHECK(c.t_to > 1);
  CHECK(reach_y(c).first <= 0.5);   // the flank's start (y 0)
  CHECK(reach_y(c).second >= 59.5);  // the flank's end, y 60 (with the old cap of 20% an end: y 58)
  CHECK(c.coverage > mid.coverage + 0.1);
  CHECK(machinable(c));
  double overcut = 0;
  for (const double d : c.machined.design_deviation)
    if (std::isfinite(d)) overcut = std::max(overcut, -d);
  CHECK(overcut <= po.tolerance);
  CHECK(c.fit.tool.D == mid.fit.tool.D);  // the tool held
  // The ε reported is the kept motion's own (eq. 13 on its rails), whichever candidate it came from.
  CHECK(c.fit.eps_opt.max == doctest::Approx(sample_error(s.phi, c.fit.rails, c.fit.tool, po.fit).max).epsilon(1e-6));
  CHECK(s.lowest_tip_z(c.fit.rails) >= -3 + 0.005 - 1e-6);  // clear of the floor
  // Not continued (CoverOptions::continue_ends off; nothing else to offer here): as it was.
  co.continue_ends = false;
  std::vector<PatchFit> kept{mid};
  CHECK(finish_cover(s.phi, kept, co).empty());
  CHECK(kept[0].t_from == 0);
  CHECK(kept[0].t_to == 1);
}

// test::steep_flank (the plane x = 0.25 z, y 0..60, z 0..30 mm) over its floor z <= 0, the tool on
// its +x side: they meet at 76 degrees. A flat end square to an axis along the flank dips with its
// rim away from it: a Ø10 tip leaves its rim at the flank 2.4 mm above the floor. Patches from axis
// lines, general tools up to Ø10, judged against the floor within 0.02 mm.
struct SteepFlankCover {
  TriMesh phi_mm = test::steep_flank();
  Similarity fr = unit_diagonal_frame(phi_mm);
  SurfaceIndex phi{transformed(phi_mm, fr)};
  SurfaceIndex floor{to_unit(test::floor_under_leaning_flank(), fr)};
  Eigen::Vector3d up = Eigen::Vector3d(0.25, 0, 1).normalized(), n = Eigen::Vector3d(1, 0, -0.25).normalized();
  PatchOptions po;
  SteepFlankCover(const SteepFlankCover&) = delete;  // po holds &floor
  SteepFlankCover() {
    po.fit.shape = ToolShape::General;
    po.fit.constraints.max_radius = fr.length_to_unit(5);
    po.fit.check.part = &floor;
    po.fit.check.tolerance = fr.length_to_unit(0.02);
    po.fit.check.floor_reach = 1;
    po.fit.check.floor_height = fr.length_to_unit(0.01);
    po.tolerance = fr.length_to_unit(0.02);
    po.orient_by_part = true;
  }
  // The patch fitted from lines 5 mm off the flank along its normal, `along` mm up it from z = `z0`.
  PatchFit fitted(double z0, double along) const {
    PatchSpec spec;
    spec.name = "p";
    for (double y : {3.0, 30.0, 57.0}) {
      const Eigen::Vector3d a = Eigen::Vector3d(0.25 * z0, y, z0) + 5 * n;
      spec.lines.push_back({fr.to_unit(a), fr.to_unit(a + along * up)});
    }
    return fit_patch(phi, spec, po);
  }
  // The lowest and highest z (mm) of the flank a patch brings within 0.02 mm.
  std::pair<double, double> reach(const PatchFit& f) const {
    double lo = INFINITY, hi = -INFINITY;
    for (size_t v = 0; v < phi_mm.vertices.size(); ++v)
      if (std::isfinite(f.machined.design_deviation[v]) && std::abs(f.machined.design_deviation[v]) <= po.tolerance)
        lo = std::min(lo, phi_mm.vertices[v].z()), hi = std::max(hi, phi_mm.vertices[v].z());
    return {lo, hi};
  }
  double lowest(const PatchFit& f) const { return reach(f).first; }
  double union_coverage(const std::vector<PatchFit>& c) const {
    std::vector<const MachinedSurface*> ms;
    for (const PatchFit& f : c) ms.push_back(&f.machined);
    return coverage(phi.mesh(), union_deviation(ms, phi_mm.vertices.size()).deviation, po.tolerance);
  }
  // The last pass's options: the tool's end swept, a narrow tip of Ø1.5 mm.
  CoverOptions cover_options() const {
    CoverOptions co;
    co.patch = po;
    co.end = ToolEnd{};
    co.floor_tip = fr.length_to_unit(0.75);
    co.continue_ends = false;  // the motions run over the flank's whole width
    return co;
  }
};

TEST_CASE("detection's last pass fits a wide tip again narrow where another patch machines the flank above, and it reaches lower") {
  // SteepFlankCover. The cover: a patch fitted from lines with a tool up to Ø10 (z 2.5 to 28 mm),
  // and one from lines higher up the flank. Alone, a narrow tip on the floor cost the first patch as
  // much at the top of the flank as it brought at the bottom (its cutter as long, 2 mm lower);
  // against the patch above, the last pass (floor_tip Ø1.5) fits it again so, and the union grows by
  // the rows it reaches lower.
  const SteepFlankCover s;
  const Similarity& fr = s.fr;
  const PatchFit wide = s.fitted(0, 30), above = s.fitted(12, 20);
  REQUIRE(machinable(wide));
  REQUIRE(machinable(above));
  const auto tip_mm = [&](const PatchFit& f) { return 2 * fr.length_to_mm(std::min(f.fit.tool.d(0), f.fit.tool.d(1))); };
  CoverOptions co = s.cover_options();
  co.reach_further = false;
  const std::vector<PatchFit> before{wide, above};
  std::vector<PatchFit> cover = before;
  const std::vector<size_t> replaced = finish_cover(s.phi, cover, co);
  MESSAGE("wide: tip Ø", tip_mm(wide), " mm, lowest z ", s.lowest(wide), " mm; after the pass: tip Ø", tip_mm(cover[0]),
          " mm, lowest z ", s.lowest(cover[0]), " mm; union ", s.union_coverage(before), " -> ", s.union_coverage(cover),
          "; the patch above: lowest z ", s.lowest(above), " -> ", s.lowest(cover[1]), " mm, its cutter made ",
          fr.length_to_mm(cover[1].tip_lengthened), " mm longer at its tip");
  CHECK(s.lowest(wide) >= 2.0);
  REQUIRE(!replaced.empty());
  CHECK(replaced[0] == 0);
  CHECK(tip_mm(cover[0]) <= 1.5 + 1e-6);
  CHECK(s.lowest(cover[0]) <= 1.0);
  CHECK(s.union_coverage(cover) > s.union_coverage(before) + 0.02);
  CHECK(machinable(cover[0]));
  // The patch above, judged against the narrow one below it: each variant of its floor pass is
  // offered longer at its tip, not only the one that brings most (that one reached z 11.5 mm, 1 mm
  // longer): 4 mm longer, it reaches z 8.5 mm.
  REQUIRE(replaced == std::vector<size_t>{0, 1});
  CHECK(s.lowest(cover[1]) <= 9.0);
  CHECK(fr.length_to_mm(cover[1].tip_lengthened) >= 3.0);
  CHECK(machinable(cover[1]));
  // Without the floor pass (no end swept): nothing to offer.
  co.end.reset();
  std::vector<PatchFit> plain = before;
  CHECK(finish_cover(s.phi, plain, co).empty());
}

TEST_CASE("detection's last pass judges a patch again once a patch after it was replaced, and the union grows") {
  // SteepFlankCover, cutters up to 31 mm. The cover: a patch high up the flank (a Ø10 tip at z 16
  // mm, 13.5 mm long: up to z 29) judged first, and one up the whole flank (Ø10 tip: from z 2.5 mm to
  // the top) after it. First sweep: the high patch's cutter made longer brings nothing (the long patch
  // machines the top); the long patch fitted again narrow on the floor stands 2 mm lower and reaches
  // z 0.5 mm, its top now short of the flank's. The second sweep judges the high patch again, against
  // that: its cutter made longer machines the top strip.
  SteepFlankCover s;
  s.po.fit.constraints.max_length = s.fr.length_to_unit(31);
  const Similarity& fr = s.fr;
  const PatchFit high = s.fitted(16, 13.5), whole = s.fitted(0, 31);
  REQUIRE(machinable(high));
  REQUIRE(machinable(whole));
  CHECK(s.reach(high).second == doctest::Approx(29));
  CHECK(s.reach(whole) == std::pair{2.5, 30.0});
  CoverOptions co = s.cover_options();
  const auto finished = [&](int sweeps, std::vector<size_t>& seen, std::vector<size_t>& replaced) {
    co.finish_sweeps = sweeps;
    std::vector<PatchFit> cover{high, whole};
    replaced = finish_cover(s.phi, cover, co, [&](size_t k, double) { seen.push_back(k); });
    MESSAGE(sweeps, " sweeps: union ", s.union_coverage({high, whole}), " -> ", s.union_coverage(cover), "; high z ",
            s.reach(cover[0]).first, "..", s.reach(cover[0]).second, " mm, made ", fr.length_to_mm(cover[0].reach_lengthened),
            " mm longer; whole z ", s.reach(cover[1]).first, "..", s.reach(cover[1]).second, " mm");
    return cover;
  };
  std::vector<size_t> seen1, replaced1, seen3, replaced3;
  const std::vector<PatchFit> one = finished(1, seen1, replaced1), three = finished(3, seen3, replaced3);
  // One sweep: the long patch replaced, narrow on the floor; its top and the high patch's stop short.
  CHECK(seen1 == std::vector<size_t>{0, 1});
  CHECK(replaced1 == std::vector<size_t>{1});
  CHECK(s.reach(one[1]).first <= 1.0);
  CHECK(s.reach(one[1]).second < 29);
  CHECK(s.reach(one[0]).second == doctest::Approx(29));
  // Three: the high patch judged again and made longer (the second sweep), then the long one judged
  // again against it; nothing was replaced since, so no third sweep.
  CHECK(seen3 == std::vector<size_t>{0, 1, 0, 1});
  CHECK(replaced3 == std::vector<size_t>{1, 0});
  CHECK(s.reach(three[0]).second == doctest::Approx(30));
  CHECK(three[0].reach_lengthened > 0);
  CHECK(machinable(three[0]));
  CHECK(s.union_coverage(three) > s.union_coverage(one) + 0.015);
}

TEST_CASE("a tip lengthened towards a floor and ground back where it meets it reports the net change against the fitted tool") {
  // The upright fit's tip at z = 0, a floor at z = -0.5 mm: made 2 mm longer, the tip would stand
  // 1.5 mm in the floor; with_check grinds it back to the floor, a net 0.5 mm longer than fitted
  // (less the check tolerance's margin). The same 2 mm over a floor at z = -3 mm stays.
  Setup s;
  PatchFit base;
  base.fit = optimize_motion(s.phi, s.initial, s.o);  // tip (a) at z = 0
  const double e = s.fr.length_to_unit(2.0);
  for (const double floor_z : {-0.5, -3.0}) {
    const SurfaceIndex floor(to_unit(test::box_mesh({0, -20, -10}, {30, 80, floor_z}, 4), s.fr));
    const PatchOptions po = s.over_hub(floor);
    const std::optional<PatchFit> longer = lengthened_at_tip(base, po, e);
    REQUIRE(longer.has_value());
    const PatchFit f = with_check(s.phi, *longer, po);
    const double net_mm = s.fr.length_to_mm(f.fit.rails.length - base.fit.rails.length);
    const double tip_z = s.lowest_tip_z(f.fit.rails);
    MESSAGE("floor at z = ", floor_z, " mm: tip at z = ", tip_z, " mm, lengthened ", s.fr.length_to_mm(f.tip_lengthened),
            " mm, shortened ", s.fr.length_to_mm(f.tip_shortened), " mm, net ", net_mm, " mm");
    CHECK(f.check_intrusion <= 0);
    CHECK(f.tip_shortened == 0.0);
    CHECK(s.fr.length_to_mm(f.tip_lengthened) == doctest::Approx(net_mm).epsilon(1e-9));
    if (floor_z > -1) {
      CHECK(net_mm > 0.3);
      CHECK(net_mm < 0.5);
      CHECK(tip_z > -0.5);
    } else {
      CHECK(net_mm == doctest::Approx(2.0).epsilon(1e-9));
    }
  }
}

TEST_CASE("a shank narrower than a tapered cutter's end is checked against the flank that goes on above the end") {
  // A cone Ø1.74 widening to Ø8.66 mm over 16.2 mm (the HECC impeller's auto-2), axis along z, its
  // side on the plane flank x = -(r0 + k z) that goes on 5 mm above the cutter's end; a Ø8 shank
  // beyond the end. The shank's start stands (4.33 - 4) / sqrt(1 + k^2) = 0.323 mm off the flank,
  // inside the 0.5 mm clearance (the collision check found the impeller's 0.435 mm off). The part
  // points nearest to the shank's first axis point lie below the cutter's end within its radius (the
  // cutter's alone) and hid the flank above it; the next sample, 2 mm up, is clear of the diverging
  // flank: the fit's check saw 0.073 mm (its cutter rims), now 0.293 (0.177 plus the samples' sag).
  const double L = 16.2, r0 = 0.87, r1 = 4.33, k = (r1 - r0) / L, top = L + 5;
  const TriMesh flank_mm = test::grid_mesh(41, 21, [&](int i, int j) {  // faces towards +x, the tool
    const double y = -20 + i, z = top * j / 20.0;
    return Eigen::Vector3d(-(r0 + k * z), y, z);
  });
  const Similarity fr = unit_diagonal_frame(flank_mm);
  const SurfaceIndex part(transformed(flank_mm, fr));
  CheckSurface c;
  c.part = &part;
  c.tolerance = fr.length_to_unit(0.02);
  c.clearance = fr.length_to_unit(0.5);
  for (int q = 0; q <= 15; ++q) c.body.emplace_back(fr.length_to_unit(2.0 * q), fr.length_to_unit(4.0));  // Ø8 over 30 mm
  c.up = Eigen::Vector3d::UnitZ();
  std::vector<AxisLine> lines;
  for (double y : {-10.0, 0.0, 10.0}) lines.push_back({fr.to_unit({0, y, 0}), fr.to_unit({0, y, L})});
  FitOptions o;
  o.shape = ToolShape::Cone;
  const Rails rails = rails_from_lines(lines, 0, 0, o);
  ToolRadius cone;
  cone.shape = ToolShape::Cone;
  cone.D = {fr.length_to_unit(r0), fr.length_to_unit(r1)};
  for (const bool enclose : {false, true}) {
    const CheckProfile p = check_profile(rails, cone, c, 20, 30, enclose);
    double worst = -INFINITY;
    bool body = false;
    for (size_t i = 0; i < p.intrusion.size(); ++i)
      if (p.intrusion[i] > worst) worst = p.intrusion[i], body = p.body[i];
    MESSAGE(std::string(enclose ? "enclosing" : "fit's"), " samples: worst intrusion ", fr.length_to_mm(worst), " mm (",
            std::string(body ? "shank or holder" : "cutter"), ")");
    CHECK(body);
    CHECK(fr.length_to_mm(worst) > 0.15);  // 0.5 - 0.323 = 0.177 inside the clearance
    CHECK(fr.length_to_mm(worst) < 0.35);
  }
}

TEST_CASE("a ball end is checked as its ball: shortened less than a flat end over the same hub" * doctest::test_suite("heavy")) {
  Setup s;
  const SurfaceIndex hub(to_unit(sloping_hub(), s.fr));
  PatchOptions po = s.over_hub(hub);
  po.fit.check.ball_tip = true;
  po.machined.end = ToolEnd{EndKind::Ball, 0, s.fr.length_to_mm(1.0)};
  const PatchSpec spec = s.upright();
  const PatchFit f = fit_patch(s.phi, spec, po);
  // The Ø10 ball's centre must stay 5 mm from the hub's plane z = 0.3 x; for the axis at x = 5: (z_tip + 5 - 1.5) / 1.044 >= 5, z_tip >= 1.72 mm (a flat end: 3 mm).
  const double tip_z = s.lowest_tip_z(f.fit.rails);
  MESSAGE("ball: tip at z = ", tip_z, " mm, shortened ", s.fr.length_to_mm(f.tip_shortened), " mm");
  CHECK(f.check_intrusion <= 0);
  CHECK(!f.check_refused);
  CHECK(tip_z > 1.7);
  CHECK(tip_z < 2.9);
}

TEST_CASE("a fin 0.01 mm inside the shank's clearance, between two of the fit's body samples: seen, trimmed, and the collision check agrees" * doctest::test_suite("heavy")) {
  // The shank (Ø6, z 20-40 over the upright motion) passes a thin fin at z 24.45-24.55 whose edge
  // is 3.99 mm from the axis (clearance 1 mm: 0.01 inside it) for y >= 40. The fit's body samples
  // (every mm) are 4.015 mm from it, outside a ball's clearance; judged at the fin's point against
  // the shank's outline, 0.01 mm inside it, and the motion stops before the fin.
  Setup s;
  const TriMesh fin_mm = test::box_mesh({8.99, 40, 24.45}, {30, 80, 24.55}, 2);
  const SurfaceIndex fin(to_unit(fin_mm, s.fr)), fin_index_mm(fin_mm);
  PatchOptions po = s.checked_options(fin);
  // A shank of 20 mm here, as the collision check below has it.
  for (int k = 0; k <= 40; ++k) po.fit.check.body.emplace_back(s.fr.length_to_unit(k), s.fr.length_to_unit(k <= 20 ? 3.0 : 10.0));
  const PatchSpec spec = s.upright();
  const auto collisions = [&](const PatchFit& f) { return collisions_mm(s, f, fin_index_mm, 20); };
  PatchOptions free = po;
  free.fit.check = {};
  const PatchFit g = fit_patch(s.phi, spec, free);
  // Unchecked, the motion runs on to y = 50: the shank passes the fin 0.99 mm off, and both the fit's
  // own samples and the trim's denser ones see it 0.01 mm inside the clearance, plus the sag of the
  // samples' spacing kept in hand (hypot(0.5, 3) - 3 = 0.041 mm).
  const CollisionReport before = collisions(g);
  REQUIRE_FALSE(before.clear());
  CHECK(before.intervals.front().component == Component::Shank);
  const CheckProfile coarse = check_profile(g.fit.rails, g.fit.tool, po.fit.check, 50, po.fit.samples_s);
  CHECK(s.fr.length_to_mm(*std::max_element(coarse.intrusion.begin(), coarse.intrusion.end())) == doctest::Approx(0.01 + std::hypot(0.5, 3.0) - 3).epsilon(0.02));
  const CheckProfile grown = check_profile(g.fit.rails, g.fit.tool, po.fit.check, 50, po.fit.samples_s, true);
  CHECK(s.fr.length_to_mm(*std::max_element(grown.intrusion.begin(), grown.intrusion.end())) == doctest::Approx(0.01 + std::hypot(0.5, 3.0) - 3).epsilon(0.02));
  // Checked: trimmed before the fin (the shank's circle keeps 1 mm from the fin's corner at y = 40),
  // and the collision check finds nothing on what is left.
  const PatchFit f = fit_patch(s.phi, spec, po);
  const double y_end = s.fr.to_mm(f.fit.rails.a.point(1)).y();
  MESSAGE("t ", f.t_from, "-", f.t_to, ", motion ends at y = ", y_end, " mm, coverage ", f.coverage, " (unchecked ", g.coverage, ")");
  CHECK(f.t_to < 0.85);
  CHECK(y_end < 39.72);
  CHECK(y_end > 38.0);
  CHECK(collisions(f).clear());
}

TEST_CASE("a fin reaching 0.5 mm into the cutter's side just above its tip, between the fit's rims: trimmed, and the collision check agrees" * doctest::test_suite("heavy")) {
  // The cutter (radius ~5 at the upright motion's axis x = 5) meets a plate at z 1.2-1.3 whose edge
  // lies 0.5 mm inside its side (x >= 9.5) for y >= 40. The fit's own cutter samples do not reach it:
  // rims at the tip and 2.5 mm above it (both 1.2 mm from the plate), spheres from 5 mm up (5.8 mm
  // from its edge). The trim judges the cutter as the collision check does and stops the motion
  // before the plate.
  Setup s;
  const TriMesh plate_mm = test::box_mesh({9.5, 40, 1.2}, {30, 80, 1.3}, 2);
  const SurfaceIndex plate(to_unit(plate_mm, s.fr)), plate_index_mm(plate_mm);
  PatchOptions po = s.checked_options(plate);
  po.fit.check.body = s.body();
  const PatchSpec spec = s.upright();
  PatchOptions free = po;
  free.fit.check = {};
  const PatchFit g = fit_patch(s.phi, spec, free);
  const CollisionReport before = collisions_mm(s, g, plate_index_mm, 10);
  REQUIRE_FALSE(before.clear());
  CHECK(before.intervals.front().component == Component::Tool);
  CHECK(before.intervals.front().max_depth_mm > 0.4);
  const CheckProfile samples = check_profile(g.fit.rails, g.fit.tool, po.fit.check, 50, po.fit.samples_s, true);
  CHECK(*std::max_element(samples.intrusion.begin(), samples.intrusion.end()) <= 0);
  const PatchFit f = fit_patch(s.phi, spec, po);
  const double tip_z = s.lowest_tip_z(f.fit.rails);
  const double y_end = s.fr.to_mm(f.fit.rails.a.point(1)).y();
  MESSAGE("t ", f.t_from, "-", f.t_to, ", motion ends at y = ", y_end, " mm, tip at z >= ", tip_z, " mm, coverage ", f.coverage,
          " (unchecked ", g.coverage, ")");
  CHECK(machinable(f));
  CHECK(collisions_mm(s, f, plate_index_mm, 10).clear());
  // Either the motion stops before the plate (the tool's circle of radius 5 about x = 5 meets its
  // corner x = 9.5, y = 40 from y = 40 - sqrt(25 - 4.5^2) = 37.82 on) or the tool is ground shorter
  // above it: most of the flank is still machined.
  CHECK(((y_end < 37.85 && y_end > 36.5) || tip_z > 1.3));
  CHECK(f.coverage > 0.5 * g.coverage);
}

TEST_CASE("a part face meeting the design surface at the cutter's tip is Φ's to judge within the tolerance of Φ, as in the collision check") {
  // The upright cylinder (radius 5, axis x = 5, tip plane z = 5) runs along Φ (x = 0) over y 10-50.
  // For y >= 30 a coarse part face leaves Φ just above the tip plane and falls away from it (a hub
  // fillet's chord at a blade's foot): from (0, y, 5 + rise) to (3, y, 4). The tip's rim dips into it
  // only next to Φ. Rising 0.01 mm, every point it enters beyond the check tolerance (0.005 mm) lies
  // within Φ's tolerance (0.02 mm) of Φ: Φ's to judge, as check_collisions and the back-simulation
  // judge it (left_to_design), and the whole motion is kept. Rising 0.2 mm (a ledge proud of the tip
  // plane), it still trims the motion where the ledge starts.
  Setup s;
  const Rails rails = upright_rails(s.fr, 5);
  const ToolRadius cylinder = cylinder_of(s.fr, 5);
  const auto fit_of = [&](const SurfaceIndex& part) {
    PatchOptions po = s.checked_options(part);
    po.tolerance = s.fr.length_to_unit(0.02);
    po.trim_gouges = true;
    po.fit.check.up = Eigen::Vector3d::UnitZ();
    PatchFit f;
    f.fit.rails = rails;
    f.fit.tool = cylinder;
    return std::make_pair(machine_and_trim(s.phi, f, po), po);
  };
  const auto chord = [&](double rise) {
    return to_unit(test::grid_mesh(2, 16, [&](int i, int j) { return Eigen::Vector3d(3.0 * i, 30 + 2.0 * j, i ? 4.0 : 5 + rise); }),
                   s.fr);
  };
  const SurfaceIndex fillet(chord(0.01)), ledge(chord(0.2));
  // The trim's own judgement: the fillet's chord enters the tip's rim by 0.0095 mm, Φ's within 0.02 mm of it.
  const auto [kept, po] = fit_of(fillet);
  const CheckProfile all = check_profile(rails, cylinder, po.fit.check, 50, po.fit.samples_s, true);
  const CheckProfile left = check_profile(rails, cylinder, po.fit.check, 50, po.fit.samples_s, true, &s.phi, po.tolerance);
  const double entered = s.fr.length_to_mm(*std::max_element(all.intrusion.begin(), all.intrusion.end()));
  MESSAGE("the fillet's chord: ", entered, " mm beyond the check tolerance counted alone; kept t ", kept.t_from, "-", kept.t_to);
  CHECK(entered > 0.002);
  CHECK(entered < 0.006);
  CHECK(*std::max_element(left.intrusion.begin(), left.intrusion.end()) <= 0);
  CHECK(kept.t_from == 0.0);
  CHECK(kept.t_to == 1.0);
  CHECK_FALSE(kept.check_trim.has_value());
  CHECK(machinable(kept));
  // The ledge: trimmed before y = 30 (t of y = 30 on the rails through y 10, 25, 40, 50 lies near 0.5).
  const PatchFit trimmed = fit_of(ledge).first;
  const double y_end = s.fr.to_mm(trimmed.fit.rails.a.point(1)).y();
  MESSAGE("the ledge: kept t ", trimmed.t_from, "-", trimmed.t_to, ", the motion ends at y = ", y_end, " mm");
  REQUIRE(trimmed.check_trim.has_value());
  CHECK_FALSE(trimmed.check_trim->body);
  CHECK(y_end < 30.5);
  CHECK(y_end > 27);
  CHECK(machinable(trimmed));
}

TEST_CASE("the collision check sees a ledge rising into the flat end under the rim, though the part's nearest point lies under the tip") {
  // The upright cylinder (radius 5, axis x = 5, tip plane z = 5) over y 10-50; for y >= 30 a face
  // from (0, y, 5 + rise) down to (3, y, 4). The part point nearest to the tip's axis point is the
  // face's far edge below the tip plane, outside the cutter (before, the check saw nothing, whatever
  // the rise). The face enters the end face under the rim next to x = 0, at most min(x, rise - (1 +
  // rise) x / 3) deep: 3 rise / (4 + rise) at x = that depth. The check finds it through the nearest
  // points in thin slabs over the tip plane and the one nearest to the rim point above it
  // (beside_nearest_points), and measures the depth at the part point it found: 0.6 of it or more here.
  Setup s;
  PatchFit f;
  f.fit.rails = upright_rails(s.fr, 5);
  f.fit.tool = cylinder_of(s.fr, 5);
  for (const double rise : {1.0, 0.2, 0.05, 0.02, -0.1}) {
    const TriMesh ledge_mm =
        test::grid_mesh(2, 16, [&](int i, int j) { return Eigen::Vector3d(3.0 * i, 30 + 2.0 * j, i ? 4.0 : 5 + rise); });
    const CollisionReport r = collisions_mm(s, f, SurfaceIndex(ledge_mm), 10);
    const double deepest = 3 * rise / (4 + rise);
    MESSAGE("rise ", rise, " mm: ", r.intervals.size(), " intervals, ", r.intervals.empty() ? 0.0 : r.intervals.front().max_depth_mm,
            " mm deep of ", deepest);
    if (rise < 0) {  // below the tip plane: clear
      CHECK(r.clear());
      continue;
    }
    REQUIRE(r.intervals.size() == 1);
    CHECK(r.intervals.front().component == Component::Tool);
    CHECK(r.intervals.front().max_depth_mm > 0.6 * deepest);
    CHECK(r.intervals.front().max_depth_mm < deepest + 0.005);
    // From a pose whose rim reaches y = 30 (next to x = 0 the rim spans y +- up to 2.18 about the axis).
    const double y_first = s.fr.to_mm(f.fit.rails.a.point(r.intervals.front().pose_begin / 100.0)).y();
    CHECK(y_first > 26.5);
    CHECK(y_first <= 30.0 + 1e-9);
  }
}
