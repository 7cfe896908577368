#include "core/detect.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>

#include "core/envelope.h"
#include "core/errors.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

// Coarser than the bench (66 x 200) to keep the suite quick; still an exact envelope.
struct Case {
  const char* kind;
  const char* tool;
  RadiusProfile profile;
  bool reproduce = true;  // the written-out lines re-fit to 90%
};

double worst_overcut(const Detection& d) {
  double worst = 0;
  for (double x : d.deviation)
    if (std::isfinite(x)) worst = std::max(worst, -x);
  for (const DetectedPatch& p : d.patches)
    for (double x : p.fit.machined.omega_deviation)
      if (std::isfinite(x)) worst = std::max(worst, -x);
  return worst;
}

// Detection of cylinder tools against a part (check tolerance 0.005 mm), as `flankcam run` sets it up.
CoverOptions cylinders_with_part(const Similarity& fr, const SurfaceIndex& part, double tolerance_mm) {
  CoverOptions o;
  o.patch.tolerance = fr.length_to_unit(tolerance_mm);
  o.patch.fit.shape = ToolShape::Cylinder;
  o.patch.fit.check.part = &part;
  o.patch.fit.check.tolerance = fr.length_to_unit(0.005);
  o.patch.orient_by_part = true;
  o.patch.refit_with_check = false;
  return o;
}

// The share of the area of Φ's vertices with `in(vertex)` that detection brings within the tolerance.
template <class In>
double covered_share(const TriMesh& phi, const Detection& d, double tolerance, In in) {
  std::vector<double> area(phi.vertices.size(), 0.0);
  for (int f = 0; f < int(phi.faces.size()); ++f)
    for (int v : phi.faces[size_t(f)]) area[size_t(v)] += face_area(phi, f) / 3;
  double cut = 0, all = 0;
  for (size_t v = 0; v < area.size(); ++v) {
    if (!in(phi.vertices[v])) continue;
    all += area[v];
    if (std::isfinite(d.deviation[v]) && std::abs(d.deviation[v]) <= tolerance) cut += area[v];
  }
  return all > 0 ? cut / all : 0.0;
}

// The flank x = 0.01 (y - 30)^2 (y 0..60, z 0..60 mm), which a cylinder moving with its axis along z
// envelopes exactly, twisted below z = 30 by 0.0005 (30 - z)^2 (y - 30) / 30 mm (up to 0.45 mm at
// the foot's corners: no tool of revolution follows it there), standing on a floor z <= 0.
struct TwistedFlank {
  TriMesh mm = test::grid_mesh(41, 41, [](int j, int k) {
    const double y = 1.5 * j, z = 1.5 * k, foot = std::max(0.0, 30 - z);
    return Eigen::Vector3d(0.01 * (y - 30) * (y - 30) + 0.0005 * foot * foot * (y - 30) / 30, y, z);
  });
  Similarity fr = unit_diagonal_frame(mm);
  SurfaceIndex phi{transformed(mm, fr)};
  SurfaceIndex floor{transformed(test::box_mesh({-30, -20, -20}, {60, 80, 0}, 4), fr)};
};

// Counted from detection's progress with one exchange round: the greedy's coverage as its first
// patch is accepted, before any exchange (the same search as with exchanges: 0),
// the rounds begun, and the rounds whose patch set aside came back.
struct ExchangeRounds {
  double greedy = -1;
  int rounds = 0, returned = 0;
  std::function<void(const CoverProgress&)> progress() {
    return [this](const CoverProgress& p) {
      if (greedy < 0 && p.stage == "patch accepted" && p.patches == 1) greedy = p.coverage;
      if (p.stage.rfind("exchange 1 of 1:", 0) == 0) ++rounds;
      if (p.stage == "exchange: no better patch, the one set aside kept") ++returned;
    };
  }
};

// An exact envelope (arc motion, cone) that one patch machines nearly all of within 5e-5 of the
// diagonal, covered to the unreachable target 100% with room for `max_patches` and one exchange round.
Detection arc_cover_with_an_exchange(int max_patches, ExchangeRounds& x) {
  const test::ExactEnvelope ex = test::exact_envelope("arc", cone_profile(6, 9), 50, 150);
  const SurfaceIndex surface(ex.unit_mesh);
  CoverOptions o;
  o.patch.tolerance = 5e-5;
  o.coverage = 1.0;
  o.max_patches = max_patches;
  o.exchanges = 1;
  return detect_patches(surface, o, x.progress());
}

}  // namespace

TEST_CASE("auto detection covers an exact envelope with one patch within 1e-4 of the diagonal and no overcut" * doctest::test_suite("heavy")) {
  // twist cone and s-curve cylinder: seeds at a candidate radius on the wrong side of Φ, or off the
  // axis, fitted to 90% and 68% before the seeds were moved to the nearest axis (refine_seed).
  // The s-curve's 8 written-out lines re-fit (init: lines) to only 69%: the optimiser from the
  // interpolated rails settles elsewhere and is trimmed (a known limit of `lines`, not of detection).
  const std::vector<Case> cases = {{"arc", "cone", cone_profile(6, 9)},
                                   {"twist", "cylinder", cylinder_profile(6)},
                                   {"twist", "cone", cone_profile(6, 9)},
                                   {"s-curve", "cylinder", cylinder_profile(6), false}};
  for (const Case& c : cases) {
    const std::string name = std::string(c.kind) + " " + c.tool;
    CAPTURE(name);
    test::ExactEnvelope ex = test::exact_envelope(c.kind, c.profile, 50, 150);
    const SurfaceIndex surface(ex.unit_mesh);
    CoverOptions o;
    o.patch.tolerance = 1e-4;
    int calls = 0;
    const Detection d = detect_patches(surface, o, [&](const CoverProgress& p) {
      ++calls;
      CHECK(p.seed <= p.seeds);
    });
    CHECK(calls > 0);
    REQUIRE(d.patches.size() == 1);
    CHECK(d.stop == CoverStop::Coverage);
    CHECK(d.coverage >= 0.95);
    CHECK(worst_overcut(d) <= 1e-4);
    const DetectedPatch& p = d.patches[0];
    CHECK(p.spec.name == "auto-1");
    CHECK(p.spec.init == PatchInit::Lines);
    CHECK(int(p.spec.lines.size()) == o.lines);
    // The owner of every covered vertex is the patch; the union is that patch's deviation.
    for (size_t v = 0; v < d.owner.size(); ++v)
      if (std::isfinite(d.deviation[v])) CHECK(d.owner[v] == 0);
    CHECK(coverage(ex.unit_mesh, d.deviation, o.patch.tolerance) == doctest::Approx(d.coverage));

    // The written-out lines reproduce the patch as an init: lines patch.
    if (!c.reproduce) continue;
    PatchOptions po;
    po.tolerance = 1e-4;
    po.trim_gouges = true;
    const PatchFit again = fit_patch(surface, p.spec, po);
    CHECK(again.coverage >= 0.9);
  }
}

TEST_CASE("auto detection covers spline-tool envelopes with one patch: the seeds find the tilted axis" * doctest::test_suite("heavy")) {
  // The general (spline) tool's meridian is far from a cone: its axis leaves Φ's tangent plane and
  // is not a principal direction, so seeds in the tangent plane ranked wrong lines first (s-curve:
  // 4 patches covering 15%, helix: 5 patches). When the seeded lines' best patch brings little, the
  // seeds turned to their least F_l (orient_line) are tried as a second pool.
  const RadiusProfile spline = spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5});
  for (const std::string kind : {"s-curve", "helix"}) {
    CAPTURE(kind);
    // The bench's resolution: at 50 x 150 the s-curve's seeds stay 0.02-0.04 off the axis (the short
    // sweep's radius spread is too noisy there) and the patch is trimmed to half.
    test::ExactEnvelope ex = test::exact_envelope(kind.c_str(), spline, 66, 200);
    const SurfaceIndex surface(ex.unit_mesh);
    CoverOptions o;
    o.patch.tolerance = 1e-4;
    const Detection d = detect_patches(surface, o);
    REQUIRE(d.patches.size() == 1);
    CHECK(d.stop == CoverStop::Coverage);
    CHECK(d.coverage >= 0.95);
    CHECK(worst_overcut(d) <= 1e-4);
    // The patch's axis follows the exact motion: its middle line lies within 2 degrees of the exact
    // axis nearest to it and within 1% of the diagonal of that axis. Not on the helix: it is nearly a
    // screw motion, whose envelope is swept by a family of tools (the patch found one 0.05 away).
    if (kind == "helix") continue;
    const Rails& r = d.patches[0].fit.fit.rails;
    const Eigen::Vector3d a = r.a.point(0.5), b = r.b.point(0.5), mid = 0.5 * (a + b);
    double best = 1e9, t_best = 0;
    for (int i = 0; i <= 1000; ++i) {
      const double t = i / 1000.0;
      const double dist = (0.5 * (ex.frame.to_unit(ex.motion.a(t)) + ex.frame.to_unit(ex.motion.b(t))) - mid).norm();
      if (dist < best) best = dist, t_best = t;
    }
    const Eigen::Vector3d ea = ex.frame.to_unit(ex.motion.a(t_best)), eb = ex.frame.to_unit(ex.motion.b(t_best));
    const Eigen::Vector3d e = (eb - ea).normalized();
    CHECK(std::acos(std::min(1.0, std::abs((b - a).normalized().dot(e)))) * 180 / M_PI < 2.0);
    const Eigen::Vector3d w = mid - 0.5 * (ea + eb);
    CHECK((w - w.dot(e) * e).norm() < 0.01);
  }
}

TEST_CASE("auto detection is deterministic" * doctest::test_suite("heavy")) {
  test::ExactEnvelope ex = test::exact_envelope("s-curve", cylinder_profile(6), 40, 120);
  const SurfaceIndex surface(ex.unit_mesh);
  CoverOptions o;  // a small search: the property is the same at any size
  o.max_patches = 1;
  o.explored_seeds = 2;
  o.fitted_seeds = 1;
  const Detection d1 = detect_patches(surface, o), d2 = detect_patches(surface, o);
  REQUIRE(d1.patches.size() == d2.patches.size());
  CHECK(d1.coverage == d2.coverage);
  for (size_t k = 0; k < d1.patches.size(); ++k)
    for (size_t i = 0; i < d1.patches[k].spec.lines.size(); ++i) {
      CHECK(d1.patches[k].spec.lines[i].a == d2.patches[k].spec.lines[i].a);
      CHECK(d1.patches[k].spec.lines[i].b == d2.patches[k].spec.lines[i].b);
    }
}

namespace {
// Two envelopes of different tools along the same s-curve, one after the other in x, as one mesh
// (unit frame); the first `first` vertices are the first envelope's.
struct TwoEnvelopes {
  int first = 0;
  SurfaceIndex surface{TriMesh{}};
  TwoEnvelopes() {
    AnalyticMotionOptions mo;
    mo.kind = "twist";
    const LineMotion m = analytic_motion(mo);
    const EnvelopeGrid g1 = envelope_grid(m, cylinder_profile(6), 30, 60, 1, 0.0, 0.5);
    const EnvelopeGrid g2 = envelope_grid(m, cone_profile(4, 9), 30, 60, 1, 0.5, 1.0);
    first = int(g1.mesh.vertices.size());
    const TriMesh both = test::merged(g1.mesh, g2.mesh);
    surface = SurfaceIndex(transformed(both, unit_diagonal_frame(both)));
  }
};
}  // namespace

TEST_CASE("two exact envelopes side by side need two patches, in order along the surface, each owning its part" * doctest::test_suite("heavy")) {
  const TwoEnvelopes two;
  const SurfaceIndex& surface = two.surface;
  const int off = two.first;
  CoverOptions o;
  o.patch.tolerance = 2e-4;
  o.max_patches = 3;
  const Detection d = detect_patches(surface, o);
  CHECK(d.patches.size() >= 2);
  CHECK(d.coverage >= 0.85);
  CHECK(worst_overcut(d) <= 2e-4);
  // Machining order along x: auto-1 owns the first half of the vertices mostly.
  REQUIRE(d.patches.size() >= 2);
  CHECK(d.patches[0].spec.name == "auto-1");
  CHECK(d.patches[1].spec.name == "auto-2");
  int first_half_by_1 = 0, first_half = 0;
  for (int v = 0; v < off; ++v)
    if (d.owner[size_t(v)] >= 0) ++first_half, first_half_by_1 += d.owner[size_t(v)] == 0;
  CHECK(first_half_by_1 > first_half / 2);
}

TEST_CASE("an uncovered region searched as a surface of its own gives a candidate the round can take" * doctest::test_suite("heavy")) {
  // The two envelopes of the test above; once the first patch covers one, the other is an uncovered
  // region. Searched always (region_below 1): it is searched once, and the patch found on it alone
  // (its lines within it) is the second patch and covers more than the whole surface's best
  // (97.2% against 96.3%).
  const TwoEnvelopes two;
  const SurfaceIndex& surface = two.surface;
  CoverOptions o;
  o.patch.tolerance = 2e-4;
  o.max_patches = 2;
  o.region_below = 1;
  const Detection d = detect_patches(surface, o);
  o.regions = 0;
  const Detection without = detect_patches(surface, o);
  MESSAGE("regions searched ", d.regions_searched, ", patches from them ", d.from_regions, ": coverage ", d.coverage,
          " (without: ", without.coverage, ")");
  CHECK(without.regions_searched == 0);
  CHECK(d.regions_searched == 1);
  CHECK(d.patches.size() == 2);
  CHECK(d.from_regions == 1);
  CHECK(d.coverage > without.coverage + 0.005);
  CHECK(d.coverage >= 0.97);
  CHECK(worst_overcut(d) <= 2e-4);
}

TEST_CASE("a twisted strip is covered by lines laid across its width, not by lines along its least curvature" * doctest::test_suite("heavy")) {
  // The hyperbolic paraboloid z = c (x - 15)(y - 60), x 0..30 mm across, y 0..120 mm along, its
  // normal turning by 20 degrees across the width: straight lines run across it (y fixed), and a
  // cylinder of 1.5 mm along one, moved along y, follows it within 0.02 mm. Its principal directions
  // are at 45 degrees to those lines at its middle: the lines seeded around them, explored and fitted,
  // end tilted 17 degrees out of the strip's plane and machine 62% of it. Seeded across the width
  // (CoverOptions::across), the lines lie along the rulings and machine all of it.
  constexpr double c = 0.01213;  // tan(20 deg) / 30 mm
  const TriMesh mm = test::grid_mesh(21, 81, [&](int i, int j) {
    const double x = 1.5 * i, y = 1.5 * j;
    return Eigen::Vector3d(x, y, c * (x - 15) * (y - 60));
  });
  const Similarity fr = unit_diagonal_frame(mm);
  const SurfaceIndex phi(transformed(mm, fr));
  CoverOptions o;
  o.patch.tolerance = fr.length_to_unit(0.02);
  o.patch.fit.shape = ToolShape::Cylinder;
  o.radii = {fr.length_to_unit(1.5)};
  o.max_patches = 1;
  o.exchanges = 0;
  o.regions = 0;
  const Detection along = detect_patches(phi, o);
  o.across = true;
  const Detection across = detect_patches(phi, o);
  REQUIRE(across.patches.size() == 1);
  const Rails& r = across.patches[0].fit.fit.rails;
  const Eigen::Vector3d axis = (r.point(0.5, 1) - r.point(0.5, 0)).normalized();
  MESSAGE("least curvature: ", along.patches.size(), " patch(es), ", along.coverage, "; across: ", across.coverage,
          ", axis ", axis.transpose(), ", overcut ", fr.length_to_mm(across.overcut), " mm");
  CHECK(std::abs(axis.x()) >= std::cos(10 * M_PI / 180));
  CHECK(across.coverage >= 0.95);
  CHECK(across.coverage >= along.coverage + 0.2);
  CHECK(fr.length_to_mm(across.overcut) <= 0.02);
}

TEST_CASE("cover options name the bad field") {
  CoverOptions o;
  CHECK(o.validate().empty());
  // The default options with one field set: validate names that field.
  const auto names = [](const char* field, const std::function<void(CoverOptions&)>& set) {
    CoverOptions c;
    set(c);
    return c.validate().find(field) != std::string::npos;
  };
  CHECK(names("cover.coverage", [](CoverOptions& c) { c.coverage = 1.5; }));
  CHECK(names("cover.max_patches", [](CoverOptions& c) { c.max_patches = 0; }));
  CHECK(names("cover.orient_below", [](CoverOptions& c) { c.orient_below = 1.5; }));
  CHECK(names("cover.oriented_fitted", [](CoverOptions& c) { c.oriented_fitted = 2 * c.oriented_explored + 1; }));
  CHECK(names("cover.regions", [](CoverOptions& c) { c.regions = -1; }));
  CHECK(names("cover.region_min", [](CoverOptions& c) { c.region_min = 0; }));
  CHECK(names("cover.region_below", [](CoverOptions& c) { c.region_below = 2; }));
  o.oriented_lines = 0;
  CHECK(o.validate().find("cover.oriented_lines") != std::string::npos);
  o.oriented_explored = 0;
  o.oriented_fitted = 0;
  CHECK(o.validate().empty());  // no oriented pool
  o = {};
  o.max_patches = 0;
  test::ExactEnvelope ex = test::exact_envelope("arc", cylinder_profile(6), 20, 40);
  const SurfaceIndex surface(ex.unit_mesh);
  CHECK_THROWS_AS((void)detect_patches(surface, o), InputError);
}

TEST_CASE("the union deviation keeps the deepest cut and names its patch") {
  MachinedSurface a, b;
  const double nan = std::nan("");
  a.design_deviation = {1e-5, nan, 3e-4, -2e-5};
  b.design_deviation = {5e-5, 2e-5, -1e-5, nan};
  const UnionDeviation u = union_deviation({&a, &b}, 4);
  CHECK(u.owner == std::vector<int>{0, 1, 1, 0});
  CHECK(u.deviation[0] == 1e-5);
  CHECK(u.deviation[2] == -1e-5);
  CHECK(u.deviation[3] == -2e-5);
}

TEST_CASE("uncovered regions: connected parts of what is left, largest first, each cut out with a band around it") {
  // A unit square, 11 x 11 vertices 0.1 apart. Covered: the column x = 0.5 and the row y = 0.5 on
  // its right half, leaving a left block (5 x 11 vertices), and two right blocks of 5 x 5.
  const TriMesh m = test::grid_mesh(11, 11, [](int i, int j) { return Eigen::Vector3d(0.1 * i, 0.1 * j, 0); });
  std::vector<char> covered(m.vertices.size(), 0);
  for (int j = 0; j < 11; ++j) covered[size_t(j * 11 + 5)] = 1;
  for (int i = 5; i < 11; ++i) covered[size_t(5 * 11 + i)] = 1;
  const std::vector<double> area(m.vertices.size(), 1.0);
  const auto ring = vertex_rings(m);
  CHECK(ring[0] == std::vector<int>{1, 11, 12});
  const auto regions = uncovered_regions(ring, covered, area);
  REQUIRE(regions.size() == 3);
  CHECK(regions[0].vertices.size() == 55);
  CHECK(regions[1].vertices.size() == 25);
  CHECK(regions[2].vertices.size() == 25);
  CHECK(regions[0].area == 55.0);
  CHECK(regions[1].area == 25.0);
  CHECK(regions[1].vertices.front() == 6);   // the lower right block before the upper one (lowest vertex)
  CHECK(regions[2].vertices.front() == 72);
  CHECK(std::is_sorted(regions[0].vertices.begin(), regions[0].vertices.end()));
  // The lower right block (x 0.6 .. 1, y 0 .. 0.4) with 0.15 along edges around it: x 0.5 .. 1,
  // y 0 .. 0.5 but for the corner (0.5, 0.5), 0.2 away along edges: 35 vertices, 49 triangles;
  // coordinates and indices into the whole mesh kept.
  const SubSurface sub = sub_surface(m, ring, regions[1].vertices, 0.15);
  CHECK(sub.mesh.vertices.size() == 35);
  CHECK(sub.mesh.faces.size() == 49);
  REQUIRE(sub.whole.size() == 35);
  for (size_t v = 0; v < sub.whole.size(); ++v) CHECK(sub.mesh.vertices[v] == m.vertices[size_t(sub.whole[v])]);
  CHECK(std::find(sub.whole.begin(), sub.whole.end(), 5 * 11 + 5) == sub.whole.end());
  CHECK(surface_area(sub.mesh) == doctest::Approx(0.245));
  // No band: the block alone (4 x 4 squares); a band short of one edge adds nothing.
  CHECK(sub_surface(m, ring, regions[1].vertices, 0).mesh.faces.size() == 32);
  CHECK(sub_surface(m, ring, regions[1].vertices, 0.099).mesh.faces.size() == 32);
  // Nothing uncovered: no region.
  CHECK(uncovered_regions(ring, std::vector<char>(m.vertices.size(), 1), area).empty());
}

TEST_CASE("propagation from a line off the true axis runs to the surface boundary on every analytic motion") {
  for (const char* kind : {"twist", "arc", "helix", "s-curve"}) {
    CAPTURE(kind);
    test::ExactEnvelope ex = test::exact_envelope(kind, cone_profile(6, 9), 40, 120);
    const SurfaceIndex surface(ex.unit_mesh);
    // The axis at t = 0.3, slid 10% of its length along itself and turned by 1 degree: a seed as
    // detection finds it, not the exact axis.
    const Eigen::Vector3d a = ex.frame.to_unit(ex.motion.a(0.3)), b = ex.frame.to_unit(ex.motion.b(0.3));
    const Eigen::Vector3d e = (b - a).normalized(), slide = 0.1 * (b - a);
    const Eigen::Vector3d turn = e.cross(Eigen::Vector3d::UnitZ()).normalized() * std::tan(M_PI / 180) * (b - a).norm();
    const LineTrajectory tr = propagate_line(surface, a + slide, b + slide + turn);
    CHECK(tr.stop_backward == PropagationStop::Boundary);
    CHECK(tr.stop_forward == PropagationStop::Boundary);
    // Both ends of the motion are reached: the nearest exact axis positions of the first and last line.
    const auto t_of = [&](const Eigen::Vector3d& mid) {
      double best_t = 0, best = 1e9;
      for (int i = 0; i <= 400; ++i) {
        const double t = i / 400.0;
        const double d = (0.5 * (ex.frame.to_unit(ex.motion.a(t)) + ex.frame.to_unit(ex.motion.b(t))) - mid).norm();
        if (d < best) best = d, best_t = t;
      }
      return best_t;
    };
    const double t0 = t_of(0.5 * (tr.a.front() + tr.b.front())), t1 = t_of(0.5 * (tr.a.back() + tr.b.back()));
    CHECK(std::min(t0, t1) < 0.05);
    CHECK(std::max(t0, t1) > 0.95);
  }
}

namespace {
// Two separate flanks 25 mm apart, each the exact envelope of the same barrel tool: `first` and
// `second` motions, the second turned half round about z (a neighbouring blade's flank faces the
// other way) and moved beside the first. Unit frame of both.
struct TwoFlanks {
  TriMesh unit_mesh;
  int first_vertices = 0;  // vertices [0, first_vertices) are the first flank's
  Similarity frame;
};
TwoFlanks two_flanks(const char* first, const char* second, int n_s, int n_t) {
  const RadiusProfile barrel = barrel_profile(6, 1.5);
  AnalyticMotionOptions m1, m2;
  m1.kind = first;
  m2.kind = second;
  const EnvelopeGrid g1 = envelope_grid(analytic_motion(m1), barrel, n_s, n_t, 1);
  EnvelopeGrid g2 = envelope_grid(analytic_motion(m2), barrel, n_s, n_t, 1);
  const Eigen::Matrix3d half_turn = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (auto& v : g2.mesh.vertices) v = half_turn * v;
  const BoundingBox b1 = bounding_box(g1.mesh.vertices), b2 = bounding_box(g2.mesh.vertices);
  const Eigen::Vector3d shift(b1.min.x() - b2.min.x(), b1.max.y() - b2.min.y() + 25, 0);
  for (auto& v : g2.mesh.vertices) v += shift;
  TwoFlanks out;
  TriMesh both = g1.mesh;
  out.first_vertices = int(both.vertices.size());
  for (const auto& v : g2.mesh.vertices) both.vertices.push_back(v);
  for (auto f : g2.mesh.faces) both.faces.push_back({f[0] + out.first_vertices, f[1] + out.first_vertices, f[2] + out.first_vertices});
  out.frame = unit_diagonal_frame(both);
  out.unit_mesh = transformed(both, out.frame);
  return out;
}

// The one tool of a shared-tool detection, and both flanks machined. Each of the first two patches'
// own tools is held for the other; the pair that covers more keeps its tool: 97.9% of the two flanks
// within 1e-4 in 3 patches with it, 98.0% after the joint refit (kept). Holding the first patch's tool,
// fitted to the arc's flank alone, gave 91.3% (100% of that flank, 85.1% of the s-curve's), and
// 145 s of fruitless rounds and region searches with it against 35 s now.
void check_one_tool_two_flanks(const Detection& d, const TwoFlanks& tf) {
  REQUIRE(!d.patches.empty());
  CHECK(d.shared_tool);
  CHECK(d.patches.size() <= 3);
  CHECK(d.stop == CoverStop::Coverage);
  CHECK(d.coverage >= 0.95);
  CHECK(worst_overcut(d) <= 1e-4);
  // One tool: the same radii and axis length for every patch, tip at the a end of each.
  const FitResult& first = d.patches[0].fit.fit;
  for (const DetectedPatch& p : d.patches) {
    CHECK(p.fit.fit.tool.D == first.tool.D);
    CHECK(p.fit.fit.rails.length == doctest::Approx(first.rails.length).epsilon(1e-9));
  }
  // Both flanks are machined: at least 95% of the first flank's vertices lie within tolerance and 90%
  // of the second's (measured: 100% and 95.1%).
  int within[2] = {0, 0}, total[2] = {0, 0};
  for (size_t v = 0; v < d.deviation.size(); ++v) {
    const int k = int(v) < tf.first_vertices ? 0 : 1;
    ++total[k];
    within[k] += std::isfinite(d.deviation[v]) && std::abs(d.deviation[v]) <= 1e-4;
  }
  MESSAGE("flanks within 1e-4: ", within[0], " of ", total[0], ", ", within[1], " of ", total[1]);
  CHECK(within[0] >= 0.95 * total[0]);
  CHECK(within[1] >= 0.9 * total[1]);
}
}  // namespace

TEST_CASE("tool shared: two separate flanks of one barrel tool are covered by one tool in few patches" * doctest::test_suite("heavy")) {
  // The arc's flank and the s-curve's, 25 mm apart. The first two patches fit their own tools; the
  // one that covers more of both when held for the other is held for every later candidate (motion
  // only); the joint refit at the end is kept only if it covers as much.
  const TwoFlanks tf = two_flanks("arc", "s-curve", 40, 120);
  const SurfaceIndex surface(tf.unit_mesh);
  CoverOptions o;
  o.patch.tolerance = 1e-4;
  o.shared_tool = true;
  std::vector<std::string> stages;
  const Detection d = detect_patches(surface, o, [&](const CoverProgress& p) { stages.push_back(p.stage); });
  MESSAGE("shared tool: " << d.patches.size() << " patches, coverage " << d.coverage << " (tool held: "
                          << d.coverage_held_tool << ", joint refit " << std::string(d.joint_refit ? "kept" : "not kept") << ")");
  check_one_tool_two_flanks(d, tf);
  CHECK(d.coverage >= d.coverage_held_tool);
  if (d.patches.size() > 1) {
    CHECK(std::find(stages.begin(), stages.end(), "shared tool chosen") != stages.end());
    CHECK(std::find(stages.begin(), stages.end(), "refitting all patches jointly with one tool") != stages.end());
  }
}

TEST_CASE("with a part: a post standing in front of a flank splits the cover, both sides are cut and no tool enters the post" * doctest::test_suite("heavy")) {
  // The flank x = 0 (y 0..60, z 0..20 mm, normals +x) and a post in front of its middle (y 28..32),
  // its twin behind it (seeds try both sides of Φ; with the front one alone a Ø3.2 tool behind the
  // sheet cut all of it in one sweep). A sweep along the whole flank runs into the post and is trimmed
  // to one side of it; the other side needs a patch of its own (the sweep beyond the post is fitted
  // as a candidate too; without that the next round's seeds find it: 3 patches, 95.1% either way
  // here). Whatever the tool, a band around the post is out of reach.
  const TriMesh phi_mm = test::grid_mesh(61, 21, [](int j, int k) { return Eigen::Vector3d(0, 1.0 * j, 1.0 * k); });
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  const SurfaceIndex post(transformed(test::merged(test::box_mesh({1, 28, -10}, {30, 32, 100}, 4),
                                                   test::box_mesh({-30, 28, -10}, {-1, 32, 100}, 4)),
                                      fr));
  // At most 3 patches, no exchanges: beyond them tools under 1 mm sneak between post and sheet for
  // slivers of the band (6 patches, 175 fits, minutes). No region searched alone either: the one
  // searched (the band's sliver) brought nothing and made the test 200 s instead of 116 s.
  CoverOptions o = cylinders_with_part(fr, post, 0.01);
  o.max_patches = 3;
  o.exchanges = 0;
  o.regions = 0;
  const Detection d = detect_patches(phi, o);
  const double low = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.y() < 20; });
  const double high = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.y() > 40; });
  MESSAGE(d.patches.size(), " patches, coverage ", d.coverage, ", y < 20: ", low, ", y > 40: ", high,
          ", trajectories fitted ", d.seeds_tried);
  for (const DetectedPatch& p : d.patches) {
    MESSAGE(p.spec.name, ": tool radius ", fr.length_to_mm(p.fit.fit.tool.d(0.5)), " mm, t ", p.fit.t_from, "-", p.fit.t_to,
            ", coverage ", p.fit.coverage);
    CHECK(!p.fit.check_refused);
    CHECK(p.fit.check_intrusion <= 0);
  }
  CHECK(d.patches.size() >= 2);
  CHECK(low >= 0.9);
  CHECK(high >= 0.9);
}

TEST_CASE("with a part: a flank taller than the longest tool is cut in two tiers, the lower one standing on the floor" * doctest::test_suite("heavy")) {
  // The flank x = 0.01 (y - 30)^2 (y 0..60, z 0..60 mm; a cylinder moving along it with its axis
  // along z envelopes it exactly) standing on a floor z <= 0, tools at most 40 mm long. A seed line
  // reaches across the whole 60 mm; as the tool it starts it is placed twice, its tip on the floor
  // and its far end at the top edge, each tier a candidate of its own. Without the placement the fit
  // shortens each line at an arbitrary end: 3 patches, 67.1%, stopped without progress (`flankcam
  // fit` of this job; 2 patches, 97.5% with it).
  const TriMesh phi_mm = test::grid_mesh(41, 41, [](int j, int k) {
    const double y = 1.5 * j;
    return Eigen::Vector3d(0.01 * (y - 30) * (y - 30), y, 1.5 * k);
  });
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  const SurfaceIndex floor(transformed(test::box_mesh({-30, -20, -20}, {60, 80, 0}, 4), fr));
  CoverOptions o = cylinders_with_part(fr, floor, 0.02);
  o.patch.fit.constraints.max_length = fr.length_to_unit(40);
  const Detection d = detect_patches(phi, o);
  const double low = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.z() < 15; });
  const double high = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.z() > 45; });
  MESSAGE(d.patches.size(), " patches, coverage ", d.coverage, ", z < 15: ", low, ", z > 45: ", high,
          ", trajectories fitted ", d.seeds_tried);
  for (const DetectedPatch& p : d.patches) {
    CHECK(!p.fit.check_refused);
    CHECK(p.fit.check_intrusion <= 0);
    CHECK(fr.length_to_mm(p.fit.fit.rails.length) <= 40 + 1e-6);
  }
  CHECK(d.patches.size() >= 2);
  CHECK(low >= 0.9);
  CHECK(high >= 0.9);
  CHECK(d.coverage >= 0.95);
}

TEST_CASE("with a part: a flank twisted near its foot is cut above the twist by a tool ground shorter at its tip" * doctest::test_suite("heavy")) {
  // The twisted flank (TwistedFlank) on its floor. The holder is away from the floor, so the tool's
  // tip is at the foot. A tool as high as the flank (61 mm) fits the top and gouges the twisted foot,
  // and the trim in t keeps only t 0.39-0.71: one patch brings 35% of the flank, 39% of its top
  // (z > 36), within 0.02 mm. The axis cut shorter at the tool's tip, tool and motion fitted again
  // over what it still reaches: 52%, and 72% of the top (the rest lies beyond the propagated sweep,
  // which the twist ends, not beyond the tool).
  const TwistedFlank t;
  const TriMesh& phi_mm = t.mm;
  const Similarity& fr = t.fr;
  CoverOptions o = cylinders_with_part(fr, t.floor, 0.02);
  o.max_patches = 1;
  o.exchanges = 0;  // the first patch as found
  const Detection d = detect_patches(t.phi, o);
  REQUIRE(d.patches.size() == 1);
  const PatchFit& f = d.patches[0].fit;
  const double top = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.z() > 36; });
  MESSAGE("coverage ", d.coverage, ", z > 36: ", top, ", tool length ", fr.length_to_mm(f.fit.rails.length), " mm, t ",
          f.t_from, "-", f.t_to, ", overcut ", fr.length_to_mm(d.overcut), " mm");
  CHECK(machinable(f));
  CHECK(fr.length_to_mm(f.fit.rails.length) <= 50);  // ground off at its tip, not the flank's 60 mm
  CHECK(top >= 0.6);
  CHECK(d.coverage >= 0.45);
  CHECK(fr.length_to_mm(d.overcut) <= 0.02);
  // The tool's tip stands above the foot's worst twist: the lowest point it brings within tolerance.
  double lowest = INFINITY;
  for (size_t v = 0; v < phi_mm.vertices.size(); ++v)
    if (std::isfinite(d.deviation[v]) && std::abs(d.deviation[v]) <= o.patch.tolerance)
      lowest = std::min(lowest, phi_mm.vertices[v].z());
  MESSAGE("lowest point within tolerance: z ", lowest, " mm");
  CHECK(lowest > 10);
}

TEST_CASE("an exchange round that finds no better patch returns the one set aside" * doctest::test_suite("heavy")) {
  // An exact envelope (arc motion, cone): one patch machines nearly all of it within 5e-5 of the
  // diagonal (all of it within 1e-4, its motion continued past Φ's ends); the target 100% is not
  // reached, so the round at max_patches sets that patch aside and searches again from the whole
  // surface. Nothing brings more than the patch set aside: it returns to its place, and the cover is
  // the greedy's exactly.
  ExchangeRounds x;
  const Detection d = arc_cover_with_an_exchange(1, x);
  const double greedy = x.greedy;
  const int rounds = x.rounds, returned = x.returned;
  MESSAGE("greedy ", greedy, "; after the round: ", d.coverage, ", ", d.exchanged, " exchanged");
  REQUIRE(d.patches.size() == 1);
  CHECK(rounds == 1);
  CHECK(returned == 1);
  CHECK(d.exchanged == 0);
  CHECK(d.stop == CoverStop::MaxPatches);
  CHECK(greedy > 0.95);
  CHECK(d.coverage == doctest::Approx(greedy).epsilon(1e-12));
  CHECK(worst_overcut(d) <= 1e-4);
}

TEST_CASE("a cover that finds no further patch short of max_patches still has its exchange rounds" * doctest::test_suite("heavy")) {
  // The arc envelope of the test above with room for 3 patches: after the first, no round brings
  // 0.5% more, and detection used to stop there. Now the exchange round runs as at max_patches: the
  // patch is set aside, nothing better is found, it returns; the stop is still "no progress".
  ExchangeRounds x;
  const Detection d = arc_cover_with_an_exchange(3, x);
  MESSAGE("greedy ", x.greedy, "; ", d.patches.size(), " patch(es), ", d.coverage, ", rounds ", x.rounds, ", returned ", x.returned);
  CHECK(d.patches.size() == 1);
  CHECK(d.stop == CoverStop::NoProgress);
  CHECK(x.rounds == 1);
  CHECK(x.returned == 1);
  CHECK(d.coverage == doctest::Approx(x.greedy).epsilon(1e-12));
}

TEST_CASE("an exchange round at max_patches replaces the weakest patch by one that brings more" * doctest::test_suite("heavy")) {
  // The twisted flank of the test above with one patch at most: the greedy's patch, found first, is
  // set aside in one exchange round, and the round's search from the whole surface finds a patch
  // bringing more (49.3% -> 56.0% within 0.02 mm; 51.7% -> 56.6% before session 46's changes to the
  // trims and the collision check), which takes its place.
  const TwistedFlank t;
  CoverOptions o = cylinders_with_part(t.fr, t.floor, 0.02);
  o.max_patches = 1;
  o.exchanges = 1;
  ExchangeRounds x;
  const Detection d = detect_patches(t.phi, o, x.progress());
  const double greedy = x.greedy;
  const int rounds = x.rounds, returned = x.returned;
  MESSAGE("greedy ", greedy, "; after exchanges: ", d.patches.size(), " patches, ", d.coverage, ", ", d.exchanged,
          " exchanged, overcut ", t.fr.length_to_mm(d.overcut), " mm");
  CHECK(d.patches.size() == 1);
  CHECK(rounds == 1);
  CHECK(greedy > 0.45);
  CHECK(d.exchanged == 1);
  CHECK(returned == 0);
  CHECK(d.coverage >= greedy + 0.03);
  double sum = 0;
  for (const DetectedPatch& p : d.patches) {
    CHECK(machinable(p.fit));
    CHECK(p.new_area > 0);
    sum += p.new_area;
  }
  CHECK(sum == doctest::Approx(d.coverage).epsilon(1e-9));
  CHECK(t.fr.length_to_mm(d.overcut) <= 0.02);
}

TEST_CASE("a motion whose contact line meets a slanted end of the surface is continued past it until the end is cut" * doctest::test_suite("heavy")) {
  // The flank x = 0.01 (y - 30)^2 (a cylinder moving with its axis along z envelopes it exactly),
  // z 0..20 mm, y from 0 to an end slanted across the rulings: 50 mm at the foot, 60 mm at the top.
  // Propagation stops where the line first reaches Φ's boundary (the foot's corner) and leaves a
  // wedge of 10 x 20 mm, 9% of Φ; the motion continued past that end cuts it (fitted there as well
  // as anywhere: the flank goes on as it is).
  const TriMesh phi_mm = test::grid_mesh(56, 21, [](int j, int k) {
    const double z = 1.0 * k, y = (50 + 0.5 * z) * j / 55.0;
    return Eigen::Vector3d(0.01 * (y - 30) * (y - 30), y, z);
  });
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  CoverOptions o;
  o.patch.tolerance = fr.length_to_unit(0.01);
  o.patch.fit.shape = ToolShape::Cylinder;
  o.max_patches = 1;
  o.exchanges = 0;
  o.regions = 0;
  const Detection d = detect_patches(phi, o);
  REQUIRE(d.patches.size() == 1);
  const PatchFit& p = d.patches[0].fit;
  const double wedge = covered_share(phi_mm, d, o.patch.tolerance, [](const Eigen::Vector3d& x) { return x.y() > 50 + 0.25 * x.z(); });
  MESSAGE("coverage ", d.coverage, ", the wedge beyond y = 50 + z / 4: ", wedge, ", t ", p.t_from, "-", p.t_to,
          ", tool radius ", fr.length_to_mm(p.fit.tool.d(0.5)), " mm");
  CHECK((p.t_from < 0 || p.t_to > 1));  // continued past an end of the optimised motion
  CHECK(wedge >= 0.9);
  CHECK(d.coverage >= 0.98);
  CHECK(worst_overcut(d) <= o.patch.tolerance);
  CHECK(machinable(p));
}

TEST_CASE("with a part: the tool's tip is pulled onto the floor and its flat end machines the flank's bottom row" * doctest::test_suite("heavy")) {
  // test::leaning_flank on its floor, cone tools, the check tolerance 0.005 mm.
  // The fit's samples of Φ leave the tip's height along the axis nearly free: without the floor's
  // pull the tip floated 0.23-0.33 mm above the floor and the bottom row (z = 0) was machined nowhere
  // within 0.02 mm (by the side envelope or by the flat end).
  const TriMesh phi_mm = test::leaning_flank();
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  const SurfaceIndex floor(transformed(test::floor_under_leaning_flank(), fr));
  const auto bottom = [](const Eigen::Vector3d& x) { return x.z() < 0.5; };
  CoverOptions o = cylinders_with_part(fr, floor, 0.02);
  o.patch.fit.shape = ToolShape::Cone;
  const Detection free = detect_patches(phi, o);
  // The floor pass: each round's best fitted again with its tip pulled onto the floor, judged with its
  // flat end swept.
  o.end = ToolEnd{};
  o.patch.fit.check.floor_reach = 1;
  o.patch.fit.check.floor_height = 0.5 * o.patch.tolerance;
  const Detection d = detect_patches(phi, o);
  const double row0_free = covered_share(phi_mm, free, o.patch.tolerance, bottom);
  const double row0 = covered_share(phi_mm, d, o.patch.tolerance, bottom);
  int by_end = 0;
  for (const DetectedPatch& p : d.patches)
    for (size_t v = 0; v < phi_mm.vertices.size(); ++v) by_end += bottom(phi_mm.vertices[v]) && p.fit.machined.design_by_end[v];
  MESSAGE("free tip: coverage ", free.coverage, ", bottom row ", row0_free, "; pulled onto the floor: ", d.patches.size(),
          " patches, coverage ", d.coverage, ", bottom row ", row0, " (", by_end, " of its vertices machined by the flat end), overcut ",
          fr.length_to_mm(d.overcut), " mm");
  CHECK(row0_free < 0.1);
  // 63% (the bottom row 0.008-0.01 mm under the rim along the middle, up to 0.06 mm towards the ends);
  // 76% when every candidate was pulled (session 33), 0% free.
  CHECK(row0 >= 0.6);
  CHECK(by_end > 0);
  CHECK(d.coverage >= 0.99);
  CHECK(fr.length_to_mm(d.overcut) <= 0.02);
  // The flat end's lowest rim point along the kept motion (the rails as kept, t 0..1): on the floor,
  // between the check tolerance into it and the tolerance above it.
  double low = INFINITY, high = -INFINITY;
  for (const DetectedPatch& p : d.patches) {
    CHECK(!p.fit.check_refused);
    CHECK(p.fit.check_intrusion <= 0);
    const Rails& r = p.fit.fit.rails;
    const double radius = fr.length_to_mm(p.fit.fit.tool.d(0));
    for (int k = 0; k <= 100; ++k) {
      const Eigen::Vector3d a = fr.to_mm(r.a.point(k / 100.0)), b = fr.to_mm(r.b.point(k / 100.0));
      const double rim = test::lowest_rim_z(a, (b - a).normalized(), radius);
      low = std::min(low, rim), high = std::max(high, rim);
    }
  }
  MESSAGE("the flat end's lowest rim point: z ", low, " to ", high, " mm");
  CHECK(low >= -0.005 - 1e-6);
  CHECK(high <= 0.02);
}

TEST_CASE("a catalogue tool held through detection covers its own exact envelopes with one patch, the motion alone fitted" * doctest::test_suite("heavy")) {
  // The catalogue's circle-segment barrel (Ø16 at the middle, profile radius 150 mm, 40 mm long),
  // held as the fixed tool: seeds at its own radii, every candidate's motion fitted to it. Measured:
  // arc and twist 1 patch, 98.97% and 98.99% within 1e-4 of the diagonal, 1 seed each (helix 2
  // patches 98.99%, s-curve 4 patches 95.6%; two flanks of it 25 mm apart 3 patches 95.8%).
  const ToolRadius mm_tool = test::catalogue_barrel_mm();
  for (const char* kind : {"arc", "twist"}) {
    CAPTURE(std::string(kind));
    const test::ExactEnvelope ex = test::exact_envelope(kind, mm_tool.profile(), 50, 150);
    const SurfaceIndex surface(ex.unit_mesh);
    CoverOptions o;
    o.patch.tolerance = 1e-4;
    ToolRadius unit_tool = mm_tool;
    for (double& d : unit_tool.D) d = ex.frame.length_to_unit(d);
    o.patch.fit.fixed_tool = unit_tool;
    o.tool_length = ex.frame.length_to_unit(40);
    const Detection d = detect_patches(surface, o);
    MESSAGE(kind, ": ", d.patches.size(), " patches, coverage ", d.coverage, ", overcut ", worst_overcut(d));
    REQUIRE(d.patches.size() == 1);
    CHECK(d.shared_tool);  // one tool: the catalogue's
    CHECK(d.stop == CoverStop::Coverage);
    CHECK(d.coverage >= 0.95);
    CHECK(worst_overcut(d) <= 1e-4);
    // The tool is the catalogue's, radii and axis length unchanged.
    const FitResult& f = d.patches[0].fit.fit;
    CHECK(f.tool.D == unit_tool.D);
    CHECK(f.rails.length == doctest::Approx(o.tool_length).epsilon(1e-12));
  }
}

TEST_CASE("with a part: a held tool longer than the flank is high stands with its tip on the floor, not centred on the flank" * doctest::test_suite("heavy")) {
  // The extruded flank x = 0.01 (y - 30)^2 (y 0..60, z 0..15 mm) on a floor z <= 0, like the HECC
  // diffuser's 15 mm vane on its hub, and a held Ø8 cylinder 25 mm long (the catalogue's cyl-d8-l25),
  // which machines the flank exactly standing upright on the floor. Centred on the flank's height its
  // tip stood 5 mm into the floor (the diffuser's first patch: 0.9%); placed like a custom tool of its
  // length, its tip end away from `up`, it stands on the floor. One patch each: 3.6% centred, 96.7%
  // on the floor (all but the bottom row).
  const TriMesh phi_mm = test::grid_mesh(61, 16, [](int j, int k) { return Eigen::Vector3d(0.01 * (j - 30) * (j - 30), j, k); });
  const Similarity fr = unit_diagonal_frame(phi_mm);
  const SurfaceIndex phi(transformed(phi_mm, fr));
  const SurfaceIndex floor(transformed(test::box_mesh({-30, -20, -20}, {40, 80, 0}, 4), fr));
  CoverOptions o = cylinders_with_part(fr, floor, 0.01);
  ToolRadius cylinder;
  cylinder.shape = ToolShape::Cylinder;
  cylinder.D = {fr.length_to_unit(4)};
  o.patch.fit.fixed_tool = cylinder;
  o.tool_length = fr.length_to_unit(25);
  o.max_patches = 1;
  o.exchanges = 0;
  o.regions = 0;
  const Detection centred = detect_patches(phi, o);  // no `up`: centred on the line
  o.up = Eigen::Vector3d::UnitZ();
  const Detection d = detect_patches(phi, o);
  MESSAGE("centred: ", centred.patches.size(), " patches, ", centred.coverage, "; on the floor: ", d.patches.size(),
          " patches, ", d.coverage, ", overcut ", fr.length_to_mm(d.overcut), " mm");
  CHECK(centred.coverage < 0.5);
  REQUIRE(d.patches.size() == 1);
  CHECK(d.coverage >= 0.95);
  CHECK(fr.length_to_mm(d.overcut) <= 0.01);
  // The tool as held, upright, its tip on the floor: between the check tolerance into it and 0.5 mm above it.
  const Rails& r = d.patches[0].fit.fit.rails;
  CHECK(r.length == doctest::Approx(o.tool_length).epsilon(1e-12));
  for (double t : {0.0, 0.5, 1.0}) {
    CAPTURE(t);
    const Eigen::Vector3d a = fr.to_mm(r.a.point(t)), b = fr.to_mm(r.b.point(t));
    CHECK((b - a).normalized().z() > 0.99);
    CHECK(a.z() >= -0.005 - 1e-6);
    CHECK(a.z() <= 0.5);
  }
}
