#include "core/envelope.h"

#include <doctest/doctest.h>

#include <functional>

#include "core/bspline.h"
#include "core/closest_point.h"
#include "core/fitting.h"
#include "core/machined_surface.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
std::vector<std::pair<std::string, RadiusProfile>> profiles() {
  return {{"cylinder", cylinder_profile(6)},
          {"cone", cone_profile(6, 9)},
          {"barrel", barrel_profile(6, 1.5)},
          {"spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5})}};
}
}  // namespace

TEST_CASE("analytic motions are rigid and start at the origin of their path") {
  for (const char* kind : {"twist", "arc", "helix", "s-curve"}) {
    CAPTURE(kind);
    AnalyticMotionOptions o;
    o.kind = kind;
    const LineMotion m = analytic_motion(o);
    for (double t = 0; t <= 1.0; t += 0.05) {
      CHECK((m.b(t) - m.a(t)).norm() == doctest::Approx(o.length).epsilon(1e-12));
      // The velocities keep the length: <da - db, a - b> = 0 (projection rule, eq. 1).
      CHECK(std::abs((m.da(t) - m.db(t)).dot(m.a(t) - m.b(t))) < 1e-6);
    }
  }
}

TEST_CASE("an envelope point satisfies the two envelope conditions and the sphere equation") {
  const Eigen::Vector3d c(1, 2, 3), c_s(0.3, -0.2, 39.9), c_t(100, 5, -7);
  for (int sheet : {1, -1}) {
    const EnvelopePoint p = envelope_point(c, c_s, c_t, 6.5, -3.0, sheet);
    REQUIRE(p.valid);
    CHECK(p.normal.norm() == doctest::Approx(1.0));
    CHECK(p.normal.dot(c_s) == doctest::Approx(3.0));  // = -d'(s)
    CHECK(std::abs(p.normal.dot(c_t)) < 1e-12);
    CHECK((p.point - c).norm() == doctest::Approx(6.5));
  }
  CHECK_FALSE(envelope_point(c, c_s, c_t, 6.5, -45.0, 1).valid);  // steeper than the axis: no characteristic
}

TEST_CASE("every profile under every motion: axis samples lie at distance d(s) from the envelope mesh" * doctest::test_suite("heavy")) {
  for (const char* kind : {"twist", "arc", "helix", "s-curve"})
    for (const auto& [name_, profile] : profiles()) {
      const std::string name = name_;  // a copy: CAPTURE's lambda may not name a structured binding (C++17)
      CAPTURE(kind);
      CAPTURE(name);
      AnalyticMotionOptions o;
      o.kind = kind;
      const LineMotion m = analytic_motion(o);
      const int ns = 41, nt = 161;
      const EnvelopeGrid g = envelope_grid(m, profile, ns, nt, 1);
      CHECK(g.invalid_points == 0);
      CHECK(g.folded_triangles == 0);
      CHECK(g.mesh.faces.size() == size_t(2 * (ns - 1) * (nt - 1)));
      const SurfaceIndex index(g.mesh);
      // Chordal (tessellation) error of a grid with ~1 mm cells on radii >= 5 mm.
      const double tessellation = 0.03;
      double worst = 0;
      for (int i = 8; i < nt - 8; i += 8)  // away from the ends, where the sheet stops
        for (int j = 0; j < ns; j += 4) {
          const double t = double(i) / (nt - 1), s = double(j) / (ns - 1);
          const Eigen::Vector3d c = (1 - s) * m.a(t) + s * m.b(t);
          worst = std::max(worst, std::abs(index.closest(c).distance - profile.d(s)));
        }
      CHECK(worst < tessellation);
    }
}

TEST_CASE("the envelope faces are oriented away from the tool axis") {
  AnalyticMotionOptions o;
  const LineMotion m = analytic_motion(o);
  const EnvelopeGrid g = envelope_grid(m, cylinder_profile(6), 10, 30, 1);
  const SurfaceIndex index(g.mesh);
  const Eigen::Vector3d c = 0.5 * (m.a(0.5) + m.b(0.5));
  const Footpoint f = index.closest(c);
  CHECK(f.normal.dot(c - f.point) > 0.99 * f.distance);  // normal points back to the axis
}

TEST_CASE("B-spline rails give the same envelope as the positions they interpolate") {
  AnalyticMotionOptions o;
  o.kind = "arc";
  const LineMotion m = analytic_motion(o);
  Eigen::MatrixXd A(200, 3), B(200, 3);
  std::vector<double> ts;
  for (int i = 0; i < 200; ++i) {
    ts.push_back(i / 199.0);
    A.row(i) = m.a(ts.back()).transpose();
    B.row(i) = m.b(ts.back()).transpose();
  }
  const LineMotion r = motion_from_rails(fit_bspline(A, ts, 40), fit_bspline(B, ts, 40));
  const RadiusProfile p = cone_profile(5, 8);
  const EnvelopeGrid ga = envelope_grid(m, p, 5, 20, 1), gb = envelope_grid(r, p, 5, 20, 1);
  for (size_t k = 0; k < ga.mesh.vertices.size(); ++k) CHECK((ga.mesh.vertices[k] - gb.mesh.vertices[k]).norm() < 1e-3);
}

TEST_CASE("a folded envelope is no machined surface: Φ where only the fold passes is not counted as machined") {
  // A Ø10 cylinder whose axis runs along the parabola y = x² / 6 (curvature radius 3 at its apex,
  // less than the tool's 5): on the concave side its envelope, the parabola's offset by 5, folds
  // into a swallowtail over the apex, whose reversed branch lies inside the swept tool. Φ is that
  // offset itself: where the tool really leaves it (farther than 5 from every axis position inside
  // the tolerance) it is machined; the stretch the tool sweeps through is overcut, and the fit had
  // called it machined within tolerance (the HECC diffuser: 23.6% claimed, 3.7% cut).
  const double rho = 3, r = 5, L = 20;
  const auto axis_at = [&](double x) { return Eigen::Vector3d(x, x * x / (2 * rho), 0); };
  const auto inward = [&](double x) { return Eigen::Vector3d(-x / rho, 1, 0).normalized(); };
  const int samples = 200;
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    const Eigen::Vector3d p = axis_at(-10 + 20 * ts[size_t(i)]);
    A.row(i) = p.transpose();
    B.row(i) = (p + Eigen::Vector3d(0, 0, L)).transpose();
  }
  const Rails rails{fit_bspline(A, ts, 24), fit_bspline(B, ts, 24), L};
  ToolRadius tool;
  tool.shape = ToolShape::Cylinder;
  tool.D = {r};
  const TriMesh phi_mesh = test::grid_mesh(161, 9, [&](int i, int j) {
    const double x = -8 + 16 * i / 160.0;
    return Eigen::Vector3d(axis_at(x) + r * inward(x) + Eigen::Vector3d(0, 0, 2 + 2 * j));
  });
  const SurfaceIndex phi(phi_mesh);
  const MachinedSurface ms = machined_surface(phi, rails, tool);
  // What the swept tool really does to each vertex: its least distance to the axis over the motion.
  int swept_through = 0, counted_there = 0, left_at_r = 0, counted_at_r = 0;
  for (size_t v = 0; v < phi_mesh.vertices.size(); ++v) {
    double nearest = INFINITY;
    for (int k = 0; k <= 4000; ++k) {
      const Eigen::Vector3d q = axis_at(-10 + 20 * k / 4000.0);
      nearest = std::min(nearest, std::hypot(phi_mesh.vertices[v].x() - q.x(), phi_mesh.vertices[v].y() - q.y()));
    }
    const bool counted = std::isfinite(ms.design_deviation[v]) && std::abs(ms.design_deviation[v]) <= 0.01;
    if (nearest < r - 0.05) ++swept_through, counted_there += counted;
    else if (nearest > r - 0.005) ++left_at_r, counted_at_r += counted;
  }
  MESSAGE("folded faces ", ms.omega.folded_triangles, "; vertices swept through ", swept_through, " (", counted_there,
          " counted machined), left at the radius ", left_at_r, " (", counted_at_r, " counted)");
  CHECK(ms.omega.folded_triangles > 0);
  CHECK(swept_through > 100);
  CHECK(counted_there == 0);
  CHECK(counted_at_r > 0.9 * left_at_r);
}

TEST_CASE("an envelope standing across Φ machines only where it passes: the distance to Ω, not its normal part") {
  // A Ø6 cylinder standing upright (axis z from -2 to +2) and travelling 10 mm along x through a flat
  // Φ (z = 0, y in [-6, 6]): its envelope is the two planes y = ±3, crossing Φ at right angles. A
  // vertex at y = 3 + e lies e from Ω, with nothing of it along Φ's normal: only the vertices on the
  // crossing lines are within tolerance; those between them the tool sweeps through.
  const double r = 3, tol = 0.01;
  const int samples = 50;
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    A.row(i) = Eigen::RowVector3d(10 * ts[size_t(i)], 0, -2);
    B.row(i) = Eigen::RowVector3d(10 * ts[size_t(i)], 0, 2);
  }
  const Rails rails{fit_bspline(A, ts, 8), fit_bspline(B, ts, 8), 4};
  ToolRadius tool;
  tool.shape = ToolShape::Cylinder;
  tool.D = {r};
  const TriMesh phi_mesh =
      test::grid_mesh(21, 49, [](int i, int j) { return Eigen::Vector3d(2 + 0.3 * i, -6 + 0.25 * j, 0); });
  const SurfaceIndex phi(phi_mesh);
  const MachinedSurface ms = machined_surface(phi, rails, tool);
  double side = 0;  // the sheet's plane: y = side * r
  for (const auto& w : ms.omega.mesh.vertices) side += w.y();
  side = side > 0 ? 1 : -1;
  int counted = 0, on_line = 0, reached_aside = 0;
  for (size_t v = 0; v < phi_mesh.vertices.size(); ++v) {
    const double y = phi_mesh.vertices[v].y(), dev = ms.design_deviation[v];
    const bool within = std::isfinite(dev) && std::abs(dev) <= tol;
    counted += within;
    if (std::abs(y - side * r) < 1e-9) {
      ++on_line;
      CHECK(within);
    } else if (std::abs(y) >= r && std::isfinite(dev)) {
      // Outside the swept slot: its distance to the crossing plane, not 0, and no overcut (the
      // vertices whose sign, Ω's offset having nothing along Φ's normal, came out as one are left
      // unjudged: the cutter does not reach them).
      ++reached_aside;
      CHECK(dev == doctest::Approx(std::abs(y - side * r)).epsilon(1e-6));
    }
  }
  CHECK(on_line == 21);
  CHECK(reached_aside > 200);
  CHECK(counted == on_line);
}

namespace {
// A tool lying along y (its axis at height z, y from -8 to 8) travelling `travel` mm along x.
Rails along_y_travelling_x(double z, double travel) {
  const int samples = 50;
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    A.row(i) = Eigen::RowVector3d(travel * ts[size_t(i)], -8, z);
    B.row(i) = Eigen::RowVector3d(travel * ts[size_t(i)], 8, z);
  }
  return {fit_bspline(A, ts, 8), fit_bspline(B, ts, 8), 16};
}

// Three sheets of Φ under a tool whose Ω is z = omega(y): the flank on Ω (x `flank`), a strip 0.5 mm
// proud of it (x `proud`) and, `below` mm under both, a sheet facing down (as a blade's flank turned
// round its edge). Ω lies across that sheet on its material side while the cutter stays off it. Each
// sheet is 11 x `n` vertices, y from y0 in steps of 0.5.
struct ThreeSheets {
  std::function<double(double)> omega;
  std::pair<double, double> flank, proud;
  double below = 1;
  double y0 = -6;
  int n = 25;
  TriMesh mesh() const {
    const auto sheet = [&](std::pair<double, double> x, double dz, double y_dir) {
      return test::grid_mesh(11, n, [&, x, dz, y_dir](int i, int j) {
        const double y = y_dir > 0 ? y0 + 0.5 * j : y0 + 0.5 * (n - 1 - j);  // the sheet below faces down
        return Eigen::Vector3d(x.first + (x.second - x.first) * i / 10, y, omega(y) + dz);
      });
    };
    return test::merged(test::merged(sheet(flank, 0, 1), sheet(proud, 0.5, 1)), sheet({flank.first, proud.second}, -below, -1));
  }
  // The flank within 1e-3 of Ω, the strip overcut by `proud_depth` (0.5 mm across Ω), the sheet
  // below not overcut. `phi` holds mesh().
  void check(const SurfaceIndex& phi, const MachinedSurface& ms, double proud_depth) const {
    const TriMesh& m = phi.mesh();
    REQUIRE(ms.tool_side == 1);
    int flanks = 0, prouds = 0, belows = 0, below_overcut = 0;
    for (size_t v = 0; v < m.vertices.size(); ++v) {
      const Eigen::Vector3d& x = m.vertices[v];
      const double dz = x.z() - omega(x.y()), dev = ms.design_deviation[v];
      if (std::abs(dz) < 1e-9) {
        ++flanks;
        CHECK(std::abs(dev) < 1e-3);
      } else if (dz > 0) {
        ++prouds;
        CHECK(dev == doctest::Approx(-proud_depth).epsilon(1e-2));
      } else {
        ++belows;
        CHECK(phi.normals()[v].z() < -0.9);  // facing down, away from the tool
        below_overcut += std::isfinite(dev) && dev < 0;
      }
    }
    CHECK(flanks == 11 * n);
    CHECK(prouds == 11 * n);
    CHECK(belows == 11 * n);
    CHECK(below_overcut == 0);
  }
};
}  // namespace

TEST_CASE("a sheet of Φ turned away from the tool is not overcut by an envelope across it: the cutter does not reach it") {
  // A Ø6 cylinder (axis at z = 3) travelling 10 mm: Ω is the plane z = 0. The sheet below is 1 mm
  // under it: before session 30 all its 275 vertices were claimed overcut by 1 mm.
  ToolRadius tool;
  tool.shape = ToolShape::Cylinder;
  tool.D = {3};
  const ThreeSheets sheets{[](double) { return 0.0; }, {2, 5}, {6, 8}};
  const SurfaceIndex phi(sheets.mesh());
  sheets.check(phi, machined_surface(phi, along_y_travelling_x(3, 10), tool), 0.5);
}

TEST_CASE("an overcut claim Ω's coarse rows cannot decide is judged at denser rows") {
  // The Ø6 cylinder travelling 100 mm, Ω tessellated at 5 rows (25 mm apart: the rows' travel allows
  // for 25 mm), the sheet below 3 mm under Ω. At Ω's rows alone no claim under 50 mm could be
  // dropped; at 65 rows (1.6 mm apart) the sheet's is, the proud strip's real overcut stays.
  ToolRadius tool;
  tool.shape = ToolShape::Cylinder;
  tool.D = {3};
  const ThreeSheets sheets{[](double) { return 0.0; }, {20, 50}, {60, 80}, 3};
  const SurfaceIndex phi(sheets.mesh());
  MachinedSurfaceOptions mo;
  mo.grid_t = 5;
  sheets.check(phi, machined_surface(phi, along_y_travelling_x(3, 100), tool, mo), 0.5);
}

TEST_CASE("a strongly tapered cutter does not overcut a sheet of Φ turned away from it either") {
  // A cone: radius d 1 at y = -8 to 7 at y = 8 (d' = 0.375; d is the radius of the spheres the tool
  // envelopes, as in the paper), axis at z = 8, travelling 10 mm: Ω is the plane below tangent to
  // those spheres, z = 8 - k d(y), k = 1 / sqrt(1 - d'^2); its generators touch the spheres short of
  // the axis' far end (y 5.2), so Φ spans y -6..4. The unreached rule's slack had allowed d'^2 times
  // the largest radius (1 mm here) for the sphere at a vertex's projection: every vertex of the sheet
  // 0.5 mm below was called overcut by ~0.46 mm (rotor 37 claimed 0.209 mm where its tapered cutter
  // stays 0.006 mm off).
  const double slope = 0.375, k = 1 / std::sqrt(1 - slope * slope);
  const auto radius = [&](double y) { return 1 + slope * (y + 8); };
  ToolRadius tool;
  tool.shape = ToolShape::Cone;
  tool.D = {radius(-8), radius(8)};
  const ThreeSheets sheets{[&](double y) { return 8 - k * radius(y); }, {2, 5}, {6, 8}, 0.5, -6, 21};
  const SurfaceIndex phi(sheets.mesh());
  // A height difference dz lies dz / sqrt(1 + (k d')^2) across the plane.
  sheets.check(phi, machined_surface(phi, along_y_travelling_x(8, 10), tool), 0.5 / std::hypot(1.0, k * slope));
}
