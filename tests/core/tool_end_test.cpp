// The tool's end (flat, ball, corner R): its profile, the surface it machines and the collision
// check of its tip face, on real geometry (a straight sweep along a flank standing on a floor).
#include "core/tool_end.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>

#include "core/collision.h"
#include "core/errors.h"
#include "core/machined_surface.h"

using namespace flankcam;

namespace {

// A straight vertical cylinder sweep: tip a(t) = (5 + 50 t, 5, 0), axis +z, length 20 (mm; the
// "unit frame" of these tests is mm).
Rails straight_rails() {
  const int n = 50;
  Eigen::MatrixXd A(n, 3), B(n, 3);
  std::vector<double> ts = uniform_parameters(n);
  for (int i = 0; i < n; ++i) {
    const double x = 5 + 50 * ts[size_t(i)];
    A.row(i) << x, 5, 0;
    B.row(i) << x, 5, 20;
  }
  return {fit_bspline(A, ts, 6), fit_bspline(B, ts, 6), 20};
}

ToolRadius cylinder(double r) {
  ToolRadius t;
  t.shape = ToolShape::Cylinder;
  t.D = {r};
  return t;
}

// The flank y = 0 (z from 0 to 20) standing on the floor z = 0 (y from 0 to 10), x in [0, 60], one
// strip of quads across the corner; normals towards the tool (+y on the flank, +z on the floor).
TriMesh flank_on_floor(double step) {
  TriMesh m;
  const int nx = int(std::lround(60 / step)) + 1, nu = int(std::lround(30 / step)) + 1;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < nu; ++j) {
      const double x = i * step, u = j * step;
      m.vertices.push_back(u < 10 ? Eigen::Vector3d(x, 10 - u, 0) : Eigen::Vector3d(x, 0, u - 10));
    }
  for (int i = 0; i + 1 < nx; ++i)
    for (int j = 0; j + 1 < nu; ++j) {
      const int v00 = i * nu + j, v01 = v00 + 1, v10 = v00 + nu, v11 = v10 + 1;
      m.faces.push_back({v00, v01, v11});
      m.faces.push_back({v00, v11, v10});
    }
  return m;
}

bool on_flank(const Eigen::Vector3d& p) { return std::abs(p.y()) < 1e-9; }
bool on_floor(const Eigen::Vector3d& p) { return std::abs(p.z()) < 1e-9; }
bool inner_x(const Eigen::Vector3d& p) { return p.x() >= 10 && p.x() <= 50; }  // away from the motion's ends

MachinedSurface machine(const SurfaceIndex& design, const std::optional<ToolEnd>& end) {
  MachinedSurfaceOptions o;
  o.end = end;
  return machined_surface(design, straight_rails(), cylinder(5), o);
}

ToolEnd corner(double r) { return {EndKind::Corner, r, 1}; }

}  // namespace

TEST_CASE("the nearest point of a polyline: its segment, past a zero-length one, and a lone point") {
  // A shank's outline: up its side (0,4)-(30,4), a zero-length step (the holder as wide as the
  // shank), out along the holder's face to (30,10), up to (70,10), in to the axis.
  const std::vector<Eigen::Vector2d> line = {{0, 4}, {30, 4}, {30, 4}, {30, 10}, {70, 10}, {70, 0}};
  PolylinePoint p = polyline_nearest(line, {10, 6});
  CHECK(p.segment == 0);
  CHECK(p.at.isApprox(Eigen::Vector2d(10, 4)));
  CHECK(p.distance == doctest::Approx(2.0));
  p = polyline_nearest(line, {28, 7});  // 2 mm from the face, 3 from the side
  CHECK(p.segment == 2);
  CHECK(p.at.isApprox(Eigen::Vector2d(30, 7)));
  CHECK(p.distance == doctest::Approx(2.0));
  p = polyline_nearest(line, {33, 2});  // beyond the corner (30, 4): the side's end, found first
  CHECK(p.segment == 0);
  CHECK(p.distance == doctest::Approx(std::hypot(3.0, 2.0)));
  p = polyline_nearest(line, {75, 5});  // beyond the far face
  CHECK(p.segment == 4);
  CHECK(p.distance == doctest::Approx(5.0));
  p = polyline_nearest({{1, 1}, {1, 1}}, {4, 5});
  CHECK(p.segment == 0);
  CHECK(p.distance == doctest::Approx(5.0));
  CHECK(std::isinf(polyline_nearest({}, {0, 0}).distance));
}

TEST_CASE("end profiles of a cylinder: flat keeps the side, corner R is a quarter circle, ball reaches the axis") {
  const std::vector<Eigen::Vector2d> side = meridian(cylinder(5), 20, 61);
  const EndProfile flat = end_profile(side, {});
  CHECK(flat.profile == side);
  CHECK(flat.end_points == 0);

  const EndProfile c = end_profile(side, corner(2));
  CHECK(c.radius == 2);
  CHECK(c.centre.x() == doctest::Approx(2).epsilon(1e-12));
  CHECK(c.centre.y() == doctest::Approx(3).epsilon(1e-9));
  CHECK(c.side_s == doctest::Approx(0.1).epsilon(1e-9));  // the side starts at z = R = 2 of 20
  CHECK(c.profile.front().x() == 0);
  CHECK(c.profile.front().y() == doctest::Approx(3).epsilon(1e-9));
  for (int k = 0; k < c.end_points; ++k) CHECK((c.profile[size_t(k)] - c.centre).norm() == doctest::Approx(2).epsilon(1e-9));
  for (size_t k = 1; k < c.profile.size(); ++k) CHECK(c.profile[k].x() > c.profile[k - 1].x());

  const EndProfile ball = end_profile(side, {EndKind::Ball, 0, 1});
  CHECK(ball.radius == doctest::Approx(5).epsilon(1e-9));
  CHECK(ball.profile.front() == Eigen::Vector2d(0, 0));
  CHECK(ball_radius(side) == doctest::Approx(5).epsilon(1e-9));
}

TEST_CASE("the ball end of a cone is tangent to the cone and to the tip plane: radius r0 cos a / (1 - sin a)") {
  for (const double alpha_deg : {5.0, -5.0, 15.0}) {
    CAPTURE(alpha_deg);
    const double k = std::sin(alpha_deg * M_PI / 180), L = 30, d0 = 4;  // sphere radii d(z) = d0 + k z
    ToolRadius t;
    t.shape = ToolShape::Cone;
    t.D = {d0, d0 + k * L};
    const std::vector<Eigen::Vector2d> side = meridian(t, L, 301);
    const double a = alpha_deg * M_PI / 180, r0 = side.front().y();
    CHECK(r0 == doctest::Approx(d0 * std::cos(a)).epsilon(1e-12));
    const double expected = r0 * std::cos(a) / (1 - std::sin(a));
    CHECK(ball_radius(side) == doctest::Approx(expected).epsilon(1e-7));
    CHECK(expected == doctest::Approx(d0 * (1 + std::sin(a))).epsilon(1e-12));
    const EndProfile b = end_profile(side, {EndKind::Ball, 0, 1});
    // Tangent to the cone: the centre is R from the cone's line (through the side's points).
    const Eigen::Vector2d p = side.front(), q = side.back(), dir = (q - p).normalized();
    const Eigen::Vector2d w = b.centre - p;
    CHECK(std::abs(w.x() * dir.y() - w.y() * dir.x()) == doctest::Approx(b.radius).epsilon(1e-6));
    CHECK(b.centre.x() - b.tip_z == doctest::Approx(b.radius).epsilon(1e-12));  // tangent to the tip plane
    // A corner radius beyond the ball's is refused, naming the key, in mm.
    CHECK_THROWS_WITH_AS((void)end_profile(side, {EndKind::Corner, 1.01 * expected, 1}),
                         doctest::Contains("tool.end.corner"), InputError);
  }
}

TEST_CASE("a flat-end cylinder with its tip face on the floor machines the flank down to the floor and does not cut the floor") {
  const TriMesh mesh = flank_on_floor(0.5);
  const SurfaceIndex design(mesh);
  const double tol = 0.01;
  const MachinedSurface with_end = machine(design, ToolEnd{}), side_only = machine(design, std::nullopt);
  double band = 0, band_end = 0, band_side = 0, floor_min = INFINITY;
  int floor_reached = 0, floor_inner = 0;
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const Eigen::Vector3d& p = mesh.vertices[v];
    if (!inner_x(p)) continue;
    if (on_flank(p) && p.z() <= 1 + 1e-9) {  // the flank's bottom band, 1 mm high, corner included
      band += 1;
      band_end += std::isfinite(with_end.design_deviation[v]) && std::abs(with_end.design_deviation[v]) <= tol;
      band_side += std::isfinite(side_only.design_deviation[v]) && std::abs(side_only.design_deviation[v]) <= tol;
    }
    if (on_floor(p) && p.y() < 10 - 1e-9) {  // under the tip face's sweep (y in [0, 10])
      ++floor_inner;
      if (std::isfinite(with_end.design_deviation[v])) {
        ++floor_reached;
        floor_min = std::min(floor_min, with_end.design_deviation[v]);
      }
    }
  }
  MESSAGE("bottom band covered within " << tol << " mm: " << band_end / band << " with the tip face, " << band_side / band
                                        << " by the side alone; floor reached " << floor_reached << " of " << floor_inner
                                        << ", deepest " << floor_min << " mm");
  CHECK(band_end / band == 1.0);
  CHECK(band_side / band < 0.75);  // the corner row is beyond the side envelope's edge
  CHECK(floor_reached == floor_inner);
  CHECK(floor_min >= -tol);
  CHECK(floor_min <= tol);
}

TEST_CASE("radii that describe no tool have no end to sweep: the machined surface is the side alone, not an error") {
  // A waist that folds the meridian (as fitting_test's): its end cannot be built ("the tool's
  // meridian must have increasing z"); detection meets such radii among its candidates and must
  // judge them (not machinable) instead of stopping the run.
  ToolRadius waist;
  waist.D = {20, 15, 15, 20};
  REQUIRE(tool_defect(waist, 20));
  CHECK_THROWS_AS((void)end_profile(meridian(waist, 20, 121), ToolEnd{}), InputError);
  const SurfaceIndex design(flank_on_floor(1.0));
  MachinedSurfaceOptions o;
  o.end = ToolEnd{};
  const MachinedSurface m = machined_surface(design, straight_rails(), waist, o);
  CHECK(std::count(m.design_by_end.begin(), m.design_by_end.end(), 1) == 0);
  CHECK(m.design_deviation.size() == design.mesh().vertices.size());
}

TEST_CASE("ball and flat ends differ at the floor corner by R (sqrt 2 - 1), and a corner R leaves a fillet of radius R" * doctest::test_suite("heavy")) {
  const TriMesh mesh = flank_on_floor(0.25);
  const SurfaceIndex design(mesh);
  const MachinedSurface flat = machine(design, ToolEnd{}), ball = machine(design, ToolEnd{EndKind::Ball, 0, 1});
  const MachinedSurface bull = machine(design, corner(2));
  double corner_flat = 0, corner_ball = 0, r_sum = 0, r_worst = 0;
  int corners = 0, fillet = 0;
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const Eigen::Vector3d& p = mesh.vertices[v];
    if (!inner_x(p)) continue;
    if (on_flank(p) && on_floor(p)) {
      ++corners;
      corner_flat = std::max(corner_flat, std::abs(flat.design_deviation[v]));
      corner_ball = std::max(corner_ball, std::abs(ball.design_deviation[v] - 5 * (std::sqrt(2.0) - 1)));
    }
    // Flank points below the fillet's top: (dev + R)^2 = R^2 + (R - z)^2 solved for R.
    if (on_flank(p) && p.z() < 1.0) {
      const double dev = bull.design_deviation[v], z = p.z();
      REQUIRE(std::isfinite(dev));
      CHECK(bull.design_by_end[v] == 1);
      const double R = z + dev + std::sqrt(2 * dev * dev + 2 * z * dev);
      r_sum += R, r_worst = std::max(r_worst, std::abs(R - 2));
      ++fillet;
    }
  }
  MESSAGE("corner point: flat " << corner_flat << " mm, ball off R(sqrt2-1) by " << corner_ball << " mm; fillet radius "
                                << r_sum / fillet << " mm (worst " << r_worst << " off 2) over " << fillet << " points");
  REQUIRE(corners > 100);
  CHECK(corner_flat < 1e-6);
  CHECK(corner_ball < 1e-4);
  CHECK(r_worst < 1e-3);
}

TEST_CASE("the collision check sees the flat tip face: a part just above the tip inside the disk is a hit, just outside its radius not") {
  ToolAssembly t;
  for (int j = 0; j <= 10; ++j) t.cutter.emplace_back(2.0 * j, 5.0);
  CollisionOptions o;
  o.gouge_tolerance_mm = 0.01;
  const auto patch_at = [](double x, double z) {  // a small horizontal square at height z centred on (x, 0)
    TriMesh m;
    m.vertices = {{x - 0.02, -0.02, z}, {x + 0.02, -0.02, z}, {x + 0.02, 0.02, z}, {x - 0.02, 0.02, z}};
    m.faces = {{0, 1, 2}, {0, 2, 3}};
    return m;
  };
  const std::vector<ToolPose> pose = {{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()}};
  // 0.05 mm above the tip plane (inside the cutter if within the radius), at radius 4.9 and 5.1.
  const CollisionReport inside = check_collisions(SurfaceIndex(patch_at(4.9, 0.05)), pose, t, o);
  REQUIRE(inside.intervals.size() == 1);
  CHECK(inside.intervals[0].component == Component::Tool);
  CHECK(inside.intervals[0].max_depth_mm == doctest::Approx(0.05).epsilon(1e-6));
  CHECK(check_collisions(SurfaceIndex(patch_at(5.1, 0.05)), pose, t, o).clear());
  CHECK(check_collisions(SurfaceIndex(patch_at(2.0, -0.05)), pose, t, o).clear());  // below the tip: not in the tool

  // A ball end (radius 5) on the same cylinder: the point 0.05 above the tip plane at radius 4.9
  // is outside the ball, the one on the axis inside it.
  std::vector<Eigen::Vector2d> side;
  for (const Eigen::Vector2d& p : t.cutter) side.push_back(p);
  ToolAssembly ball = t;
  ball.cutter = end_profile(side, {EndKind::Ball, 0, 1}, 24).profile;
  REQUIRE(ball.validate().empty());
  CHECK(check_collisions(SurfaceIndex(patch_at(4.9, 0.05)), pose, ball, o).clear());
  const CollisionReport axis = check_collisions(SurfaceIndex(patch_at(0.0, 0.05)), pose, ball, o);
  REQUIRE(axis.intervals.size() == 1);
  CHECK(axis.intervals[0].max_depth_mm == doctest::Approx(0.05).epsilon(0.05));
}
