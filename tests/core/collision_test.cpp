#include "core/collision.h"

#include <doctest/doctest.h>

#include <algorithm>

#include "core/envelope.h"
#include "core/errors.h"
#include "core/fitting.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// Cylinder cutter r = 5 over 20 mm, shank Ø12 x 30, holder cone Ø30 -> Ø50 over 40 mm.
ToolAssembly assembly() {
  ToolAssembly t;
  for (int j = 0; j <= 10; ++j) t.cutter.emplace_back(2.0 * j, 5.0);
  t.shank_length = 30, t.shank_diameter = 12;
  t.holder_length = 40, t.holder_diameter = 30, t.holder_diameter_far = 50;
  return t;
}

TriMesh plane(double size) {
  TriMesh m;
  m.vertices = {{-size, -size, 0}, {size, -size, 0}, {size, size, 0}, {-size, size, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}


// A cylinder of radius r around the line (0, y0, z0) + x e_x, x in [x0, x1], n segments.
TriMesh pipe(double r, double y0, double z0, double x0, double x1, int n) {
  TriMesh m;
  for (int e = 0; e < 2; ++e)
    for (int k = 0; k < n; ++k) {
      const double a = 2 * M_PI * k / n;
      m.vertices.emplace_back(e ? x1 : x0, y0 + r * std::cos(a), z0 + r * std::sin(a));
    }
  for (int k = 0; k < n; ++k) {
    const int k1 = (k + 1) % n;
    m.faces.push_back({k, k1, n + k1});
    m.faces.push_back({k, n + k1, n + k});
  }
  return m;
}
}  // namespace

TEST_CASE("holder cone against a plane: the exact interference depth at the cone's wide end") {
  const SurfaceIndex part(plane(500));
  const ToolAssembly t = assembly();
  CollisionOptions o;
  o.clearance_mm = 0.5;
  for (double height : {24.0, 24.9, 25.3, 26.0}) {
    CAPTURE(height);
    // Axis parallel to the plane at `height`: the cone's rim (r = 25) comes to 25 - height.
    const std::vector<ToolPose> poses = {{Eigen::Vector3d(0, 0, height), Eigen::Vector3d::UnitX()},
                                         {Eigen::Vector3d(10, 0, height), Eigen::Vector3d::UnitX()}};
    const CollisionReport r = check_collisions(part, poses, t, o);
    if (height >= 25 + o.clearance_mm) {
      CHECK(r.clear());
      continue;
    }
    REQUIRE(r.intervals.size() == 1);
    const CollisionInterval& iv = r.intervals[0];
    CHECK(iv.component == Component::Holder);
    CHECK(iv.max_depth_mm == doctest::Approx(25 - height).epsilon(1e-9));
    CHECK(iv.at.z() == doctest::Approx(0));
    CHECK(iv.at.x() - t.total_length() >= -1e-9);  // below the rim, somewhere along the 10 mm move
    CHECK(iv.at.x() - t.total_length() <= 10 + 1e-9);
    CHECK(iv.pose_begin == 0);
    CHECK(iv.pose_end == 1);
  }
}

TEST_CASE("holder cylinder against a parallel cylinder: exact depth, and the cutter alone gouges when pushed in") {
  ToolAssembly t = assembly();
  t.holder_diameter = t.holder_diameter_far = 40;  // cylinder r = 20 over z in [50, 90]
  CollisionOptions o;
  o.clearance_mm = 0.5;
  // Pipe r = 10 parallel to the tool axis (X), centre distance 29.3 -> overlap 0.7 mm with the holder,
  // 13.3 mm from the shank, 14.3 mm from the cutter.
  const SurfaceIndex part(pipe(10, 29.3, 0, -100, 300, 2880));
  const std::vector<ToolPose> poses = {{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitX()}};
  const CollisionReport r = check_collisions(part, poses, t, o);
  REQUIRE(r.intervals.size() == 1);
  CHECK(r.intervals[0].component == Component::Holder);
  CHECK(r.intervals[0].max_depth_mm == doctest::Approx(0.7).epsilon(2e-4 / 0.7));  // 2880 flats: 6e-6 mm

  // The cutter (r = 5) against the pipe moved to 14.8: 0.2 mm deep, beyond a 0.01 mm tolerance.
  ToolAssembly bare = t;
  bare.shank_length = bare.holder_length = 0;
  const SurfaceIndex close(pipe(10, 14.8, 0, -100, 300, 2880));
  const CollisionReport g = check_collisions(close, poses, bare, o);
  REQUIRE(g.intervals.size() == 1);
  CHECK(g.intervals[0].component == Component::Tool);
  CHECK(g.intervals[0].max_depth_mm == doctest::Approx(0.2).epsilon(1e-3));
}

TEST_CASE("a holder passing a thin wall between two clear poses is caught") {
  const ToolAssembly t = assembly();
  CollisionOptions o;
  o.clearance_mm = 0.5;
  // Wall 0.2 mm thick at x = 0 above z = 55 (the holder's height when the tool stands on z = 0).
  const SurfaceIndex part(test::box_mesh(Eigen::Vector3d(-0.1, -50, 55), Eigen::Vector3d(0.1, 50, 120)));
  const std::vector<ToolPose> poses = {{Eigen::Vector3d(-40, 0, 0), Eigen::Vector3d::UnitZ()},
                                       {Eigen::Vector3d(40, 0, 0), Eigen::Vector3d::UnitZ()}};
  // Each pose alone is clear.
  CHECK(check_collisions(part, {poses[0]}, t, o).clear());
  CHECK(check_collisions(part, {poses[1]}, t, o).clear());
  const CollisionReport r = check_collisions(part, poses, t, o);
  REQUIRE(!r.clear());
  bool holder = false;
  for (const auto& iv : r.intervals) {
    CHECK(iv.pose_begin == 0);
    CHECK(iv.pose_end == 1);
    holder |= iv.component == Component::Holder && iv.max_depth_mm > 20;  // the holder is cut right through
  }
  CHECK(holder);
  MESSAGE(r.positions_checked << " positions, " << r.queries << " queries");
}

TEST_CASE("a clear flank motion along an exact envelope raises no alarm, pushing the part 0.2 mm in does" * doctest::test_suite("heavy")) {
  AnalyticMotionOptions mo;
  mo.kind = "twist";
  const LineMotion m = analytic_motion(mo);
  const RadiusProfile prof = cone_profile(6, 9);
  const EnvelopeGrid g = envelope_grid(m, prof, 80, 400, 1);
  ToolAssembly t;
  const double L = (m.b(0) - m.a(0)).norm();
  for (int j = 0; j <= 40; ++j) t.cutter.emplace_back(L * j / 40, prof.d(j / 40.0));
  t.shank_length = 20, t.shank_diameter = 10;
  t.holder_length = 30, t.holder_diameter = 14, t.holder_diameter_far = 40;
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 200; ++i) {
    const double s = 0.1 + 0.8 * i / 200.0;  // inside the envelope's t range (its ends are open)
    poses.push_back({m.a(s), (m.b(s) - m.a(s)).normalized()});
  }
  CollisionOptions o;
  o.clearance_mm = 1;
  o.gouge_tolerance_mm = 0.05;  // the mesh's tessellation error is up to 0.03 mm
  const CollisionReport clear = check_collisions(SurfaceIndex(g.mesh), poses, t, o);
  for (const auto& iv : clear.intervals) MESSAGE(to_string(iv.component) << " " << iv.max_depth_mm);
  CHECK(clear.clear());

  TriMesh pushed = g.mesh;
  const auto normals = vertex_normals(g.mesh);
  // Towards the tool: the side of the normals where the axis is.
  const Eigen::Vector3d mid = 0.5 * (m.a(0.5) + m.b(0.5));
  const SurfaceIndex original(g.mesh);
  const Footpoint f = original.closest(mid);
  const double towards = (mid - f.point).dot(f.normal) > 0 ? 1 : -1;
  for (size_t v = 0; v < pushed.vertices.size(); ++v) pushed.vertices[v] += towards * 0.2 * normals[v];
  const CollisionReport gouge = check_collisions(SurfaceIndex(pushed), poses, t, o);
  REQUIRE(!gouge.clear());
  for (const auto& iv : gouge.intervals) {
    CHECK(iv.component == Component::Tool);
    CHECK(iv.max_depth_mm == doctest::Approx(0.2).epsilon(0.2));
  }
}

TEST_CASE("the assembly mesh is closed and spans the assembly") {
  const ToolAssembly t = assembly();
  const TriMesh m = assembly_mesh(t, {Eigen::Vector3d(1, 2, 3), Eigen::Vector3d::UnitY()}, 24);
  const MeshTopology topo = mesh_topology(m);
  CHECK(topo.boundary_edges == 0);
  const BoundingBox b = bounding_box(m.vertices);
  CHECK(b.max.y() - b.min.y() == doctest::Approx(t.total_length()));
  CHECK(b.max.x() - b.min.x() == doctest::Approx(50).epsilon(0.01));
}

TEST_CASE("the cutter is flat-ended: standing on a floor is no gouge, sinking into it is, by the depth") {
  // Flank cutting with the tip on the floor (a hub wall): the axis vertical, the tip on the plane z = 0.
  const SurfaceIndex part(plane(500));
  CollisionOptions o;
  o.gouge_tolerance_mm = 0.01;
  std::vector<ToolPose> poses;
  for (int i = 0; i < 5; ++i) poses.push_back({Eigen::Vector3d(10.0 * i, 0, 0.0), Eigen::Vector3d::UnitZ()});
  CHECK(check_collisions(part, poses, assembly(), o).clear());  // the spheres' caps would have reported 5 mm
  for (ToolPose& p : poses) p.tip.z() = -0.3;  // 0.3 mm into the floor
  const CollisionReport r = check_collisions(part, poses, assembly(), o);
  REQUIRE(r.intervals.size() == 1);
  CHECK(r.intervals[0].component == Component::Tool);
  CHECK(r.intervals[0].max_depth_mm == doctest::Approx(0.3).epsilon(1e-6));
}

// Issue 12 item 7: a 50 m part made the check run for hours (positions every half clearance, every
// axial sample walking every position). Far samples now skip by bisection, the work is bounded by
// CollisionOptions, and progress is reported.
TEST_CASE("a 50 m pass over a thin wall finds the wall, skips far positions, reports progress and stays within the bounds") {
  // A wall 0.6 mm thick (thinner than the clearance) 200 mm high at x = 25 m; the tool (92 mm
  // long) moves 50 m along x with its axis vertical, the tip 2 mm above the wall's foot.
  TriMesh part = test::box_mesh({25000, -100, -5}, {25000.6, 100, 195});
  const SurfaceIndex index(part);
  const ToolAssembly t = assembly();
  const std::vector<ToolPose> poses = {{Eigen::Vector3d(0, 0, 2), Eigen::Vector3d::UnitZ()},
                                       {Eigen::Vector3d(50000, 0, 2), Eigen::Vector3d::UnitZ()}};
  CollisionOptions o;
  std::vector<double> seen;
  o.progress = [&](double f) { seen.push_back(f); };
  const CollisionReport r = check_collisions(index, poses, t, o);
  CHECK(r.positions_checked == 100001);  // 50 m at half the 1 mm clearance, both ends
  // Every component passes through the wall.
  REQUIRE(r.intervals.size() == 3);
  for (const CollisionInterval& iv : r.intervals) {
    CAPTURE(to_string(iv.component));
    CHECK(iv.pose_begin == 0);
    CHECK(iv.pose_end == 1);
    CHECK(iv.at.x() >= 25000 - 1e-9);
    CHECK(iv.at.x() <= 25000.6 + 1e-9);
  }
  // Far from the wall a sample jumps ahead by its distance: the queries are a small share of
  // positions x samples (each sample needs ~log2 of the distances plus the positions near the wall).
  const double samples_times_positions = double(r.positions_checked) * 200;  // more than 100 samples
  MESSAGE(r.queries << " queries for " << r.positions_checked << " positions");
  CHECK(double(r.queries) < 0.02 * samples_times_positions);
  REQUIRE_FALSE(seen.empty());
  CHECK(std::is_sorted(seen.begin(), seen.end()));
  CHECK(seen.front() > 0);
  CHECK(seen.back() == 1.0);

  // Without the wall nothing is reported; with a tighter bound the check refuses before working.
  CHECK(check_collisions(SurfaceIndex(test::box_mesh({0, 500, -5}, {50000, 501, 195})), poses, t, CollisionOptions{}).clear());
  CollisionOptions small;
  small.max_positions = 50000;
  CHECK_THROWS_WITH_AS((void)check_collisions(index, poses, t, small),
                       doctest::Contains("collision check: the motion (50000 mm of travel and more) checked every 0.5 mm"),
                       InputError);
  CollisionOptions tiny_clearance;
  tiny_clearance.clearance_mm = 1e-4;  // 1e9 positions: refused at once, not run for hours
  CHECK_THROWS_WITH_AS((void)check_collisions(index, poses, t, tiny_clearance), doctest::Contains("raise the clearance"),
                       InputError);
}

TEST_CASE("a motion given as two poses or as a pose every half clearance reports the same collisions") {
  // The same positions, once interpolated (the bisection skips across the steps between the two
  // poses) and once as input poses (it skips across poses): the same walls, depths and points.
  TriMesh part = test::box_mesh({50, -100, -5}, {50.6, 100, 195});
  const SurfaceIndex index(part);
  const ToolAssembly t = assembly();
  const std::vector<ToolPose> one = {{Eigen::Vector3d(0, 0, 2), Eigen::Vector3d::UnitZ()},
                                     {Eigen::Vector3d(100, 0, 2), Eigen::Vector3d::UnitZ()}};
  std::vector<ToolPose> many;  // the same motion with an input pose every 0.5 mm (no positions between)
  for (int k = 0; k <= 200; ++k) many.push_back({Eigen::Vector3d(0.5 * k, 0, 2), Eigen::Vector3d::UnitZ()});
  CollisionReport a = check_collisions(index, one, t, CollisionOptions{});
  CollisionReport b = check_collisions(index, many, t, CollisionOptions{});
  CHECK(a.positions_checked == b.positions_checked);
  REQUIRE(a.intervals.size() == 3);
  REQUIRE(b.intervals.size() == 3);
  for (auto* r : {&a, &b})
    std::sort(r->intervals.begin(), r->intervals.end(),
              [](const CollisionInterval& x, const CollisionInterval& y) { return x.component < y.component; });
  for (size_t k = 0; k < a.intervals.size(); ++k) {
    CAPTURE(k);
    CHECK(a.intervals[k].component == b.intervals[k].component);
    CHECK(a.intervals[k].max_depth_mm == doctest::Approx(b.intervals[k].max_depth_mm));
    CHECK(a.intervals[k].at.x() == doctest::Approx(b.intervals[k].at.x()));
  }
}

TEST_CASE("the cutter is the union of the fitted spheres, not their radii: a steep cone's side is found where the radii fall short") {
  // A cone r(z) = 2 + 0.3 z over 10 mm, as the fit holds it: spheres d(s) centred on the axis
  // (tool_from_meridian). At z = 5 the cone's radius is 3.5 while the sphere centred there has
  // d = 3.5 / sqrt(1 + 0.3^2) = 3.353: judged by the spheres' radii the side would stand 0.147 mm
  // inside the tool the programs cut.
  std::vector<Eigen::Vector2d> cone;
  for (int k = 0; k <= 40; ++k) cone.emplace_back(0.25 * k, 2 + 0.3 * 0.25 * k);
  const double L = 10;
  const ToolRadius tool = tool_from_meridian(cone, 12);
  CHECK(tool.d(0.5) == doctest::Approx(3.5 / std::sqrt(1.09)).epsilon(1e-3));
  const std::vector<Eigen::Vector2d> cutter = cutter_union(tool, L);
  REQUIRE(cutter.size() == 121);
  CHECK(cutter.front().x() == 0.0);
  CHECK(cutter.back().x() == doctest::Approx(L));
  // Along the side the cone itself (the envelope's characteristic circles run from z = 0.6 to 8.6);
  // above, the last sphere (radius d(1) = 5 / sqrt(1.09) = 4.79 at z = 10).
  for (const Eigen::Vector2d& zr : cutter)
    if (zr.x() > 0.7 && zr.x() < 8.5) CHECK(zr.y() == doctest::Approx(2 + 0.3 * zr.x()).epsilon(1e-3));
  CHECK(cutter.back().y() == doctest::Approx(5 / std::sqrt(1.09)).epsilon(1e-3));
  // A strip at radius 3.45 over z 4.9-5 (the tool vertical, tip at the origin): 0.05 mm into
  // the cone, found; beside the spheres' radii it would be 0.1 mm clear.
  ToolAssembly t;
  t.cutter = cutter;
  TriMesh wall;
  wall.vertices = {{3.45, -3, 4.9}, {3.45, 3, 4.9}, {3.45, 3, 5}, {3.45, -3, 5}};
  wall.faces = {{0, 1, 2}, {0, 2, 3}};
  const SurfaceIndex part(wall);
  CollisionOptions o;
  o.gouge_tolerance_mm = 0.01;
  o.clearance_mm = 0.5;
  const std::vector<ToolPose> upright{{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()}};
  const CollisionReport r = check_collisions(part, upright, t, o);
  REQUIRE(r.intervals.size() == 1);
  CHECK(r.intervals[0].component == Component::Tool);
  CHECK(r.intervals[0].max_depth_mm == doctest::Approx(0.05).epsilon(0.05));
  ToolAssembly radii;
  for (int j = 0; j <= 40; ++j) radii.cutter.emplace_back(L * j / 40, tool.d(j / 40.0));
  CHECK(check_collisions(part, upright, radii, o).clear());
}

TEST_CASE("a post entering the holder through its face is found behind a nearer clear wall beside the shank") {
  // The tool stands on z = 0 along +z: cutter r 5 up to z = 20, shank r 6 up to 50, the holder's face
  // (r 15) at z = 50. A block 2.5 mm beside the shank, its top 1 mm under the face: clear by both.
  // On the other side a post 1 mm square at r 13.5-14.5 rises 1 mm through the face. The block is
  // nearer to every axis point that can reach the post (z < 77.5), so one nearest part point per
  // axis point never sees the post.
  const ToolAssembly t = assembly();
  CollisionOptions o;
  o.clearance_mm = 0.5;
  const TriMesh block = test::box_mesh({8.5, -40, 0}, {40, 40, 49});
  const TriMesh both = test::merged(block, test::box_mesh({-14.5, -0.5, 30}, {-13.5, 0.5, 51}));
  const size_t base = block.vertices.size();
  const std::vector<ToolPose> pose = {{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()}};
  CHECK(check_collisions(SurfaceIndex(block), pose, t, o).clear());
  const CollisionReport r = check_collisions(SurfaceIndex(both), pose, t, o);
  REQUIRE(r.intervals.size() == 1);
  const CollisionInterval& iv = r.intervals[0];
  CHECK(iv.component == Component::Holder);
  // Radial depth at the post's inner face, 13.5 mm off the axis, where the cone's radius is 15-15.25 mm.
  CAPTURE(iv.at.transpose());
  CHECK(iv.max_depth_mm > 1.5);
  CHECK(iv.max_depth_mm <= 1.75 + 1e-9);
  CHECK(iv.at.x() == doctest::Approx(-13.5));
  CHECK(iv.at.z() >= 49.5);
  // Lowered 0.6 mm (its top 0.4 mm above the face) the post is inside; 1.2 mm (0.2 under the face)
  // within the clearance of the face, though 7.5 mm off the shank; 1.6 mm (0.6 under it) clear.
  for (const double drop : {0.6, 1.2, 1.6}) {
    CAPTURE(drop);
    TriMesh lowered = both;
    for (size_t v = base; v < lowered.vertices.size(); ++v) lowered.vertices[v].z() -= drop;
    const CollisionReport l = check_collisions(SurfaceIndex(lowered), pose, t, o);
    CHECK(l.clear() == (drop > 1.5));
    if (drop == 1.2 && l.intervals.size() == 1) CHECK(l.intervals[0].max_depth_mm == doctest::Approx(-0.2).epsilon(1e-9));
  }
}

TEST_CASE("part under the cutter's end face is the cutter's, not the narrower shank's, and beside it under a wider shank it is the shank's") {
  // The tool stands on z = 0 along +z: cutter r 5 up to z = 20, then the shank. A post of the design
  // surface's own material (left to it, as Φ's twin is) 4.3-4.6 mm off the axis, its top 0.03 mm under
  // the cutter's end: under a Ø8 shank it is 0.3 mm from the shank's rim, yet the shank cannot reach
  // it but through the cutter (NASA rotor 37: a Ø8 shank over a Ø9.7 cutter skimming the blade's tip
  // face was held off it and its patches trimmed).
  ToolAssembly t = assembly();
  t.shank_diameter = 8;
  CollisionOptions o;
  o.clearance_mm = 0.5;
  const TriMesh post = test::box_mesh({4.3, -0.2, 10}, {4.6, 0.2, 19.97});
  const SurfaceIndex part(post);
  o.design = &part;
  o.design_within_mm = 0.05;
  const std::vector<ToolPose> pose = {{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()}};
  CHECK(check_collisions(part, pose, t, o).clear());
  // Beside the cutter (5.2-5.4 mm off the axis), 0.3 mm under the end of a Ø12 shank: the shank's face
  // is 0.3 mm above it, inside the 0.5 mm clearance.
  t.shank_diameter = 12;
  const SurfaceIndex beside(test::box_mesh({5.2, -0.2, 10}, {5.4, 0.2, 19.7}));
  o.design = nullptr;
  const CollisionReport r = check_collisions(beside, pose, t, o);
  REQUIRE(r.intervals.size() == 1);
  CHECK(r.intervals[0].component == Component::Shank);
  CHECK(r.intervals[0].max_depth_mm == doctest::Approx(-0.3).epsilon(1e-9));
}
