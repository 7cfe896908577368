#include "core/fitting.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <functional>
#include <random>

#include "core/machined_surface.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
struct Case {
  const char* motion;
  const char* profile_name;
  RadiusProfile profile;
  ToolShape shape;
};

using Exact = test::ExactEnvelope;
using test::exact_envelope;

// Perturbed by 1% of the diagonal and 2 degrees (the acceptance of issue 3).
AxisLine perturbed(const Exact& ex, double t, std::mt19937& rng) {
  std::normal_distribution<double> g;
  const Eigen::Vector3d a = ex.frame.to_unit(ex.motion.a(t)), b = ex.frame.to_unit(ex.motion.b(t));
  const Eigen::Vector3d off = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized() * 0.01;
  const Eigen::Vector3d axis = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
  const Eigen::Vector3d mid = 0.5 * (a + b) + off, d = Eigen::AngleAxisd(2 * M_PI / 180, axis) * (b - a);
  return {mid - 0.5 * d, mid + 0.5 * d};
}

// Runs `fit` on the exact envelope of every case (CAPTURE names it), with a fresh seeded generator.
void for_each_case(const std::vector<Case>& cases,
                   const std::function<void(const Case&, const Exact&, const SurfaceIndex&, std::mt19937&)>& fit) {
  for (const auto& c : cases) {
    const std::string name = std::string(c.motion) + " " + c.profile_name;
    CAPTURE(name);
    const Exact ex = exact_envelope(c.motion, c.profile);
    const SurfaceIndex surface(ex.unit_mesh);
    std::mt19937 rng(3);
    fit(c, ex, surface, rng);
  }
}

double profile_error_mm(const FitResult& r, const Exact& ex, const RadiusProfile& truth) {
  double worst = 0;
  for (double s = 0.1; s <= 0.9; s += 0.1) worst = std::max(worst, std::abs(ex.frame.length_to_mm(r.tool.d(s)) - truth.d(s)));
  return worst;
}
}  // namespace

TEST_CASE("surface-driven fits of exact envelopes reach eps <= 1e-4 for every tool shape") {
  const std::vector<Case> cases = {{"s-curve", "cylinder", cylinder_profile(6), ToolShape::Cylinder},
                                   {"arc", "cone", cone_profile(6, 9), ToolShape::Cone},
                                   {"twist", "barrel", barrel_profile(6, 1.5), ToolShape::General},
                                   {"helix", "spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5}), ToolShape::General}};
  for_each_case(cases, [](const Case& c, const Exact& ex, const SurfaceIndex& surface, std::mt19937& rng) {
    std::vector<AxisLine> lines;
    for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) lines.push_back(perturbed(ex, t, rng));
    FitOptions o;
    o.shape = c.shape;
    const FitResult r = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
    MESSAGE((std::string(c.motion) + " " + c.profile_name) << ": eps_ini " << r.eps_ini.max << " eps_opt " << r.eps_opt.max
                     << " profile error " << profile_error_mm(r, ex, c.profile) << " mm");
    CHECK(r.eps_ini.max > 1e-3);
    CHECK(r.eps_opt.max <= 1e-4);
    CHECK(r.eps_opt.samples > 2000);
    // The radius is only weakly determined on nearly developable envelopes (see FitOptions::w_anchor):
    // it comes back within the 1% (1.3-1.6 mm) the lines were perturbed by.
    CHECK(profile_error_mm(r, ex, c.profile) < 1.2);
  });
}

TEST_CASE("line-driven fits from one perturbed line reach eps <= 1e-4") {
  const std::vector<Case> cases = {{"twist", "cylinder", cylinder_profile(6), ToolShape::Cylinder},
                                   {"s-curve", "cone", cone_profile(6, 9), ToolShape::Cone},
                                   {"helix", "barrel", barrel_profile(6, 1.5), ToolShape::General},
                                   {"helix", "spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5}), ToolShape::General}};
  for_each_case(cases, [](const Case& c, const Exact& ex, const SurfaceIndex& surface, std::mt19937& rng) {
    const AxisLine l = perturbed(ex, 0.5, rng);
    const ExploredLine best = explore_line(surface, l.a, l.b);
    const LineTrajectory tr = propagate_line(surface, best.a, best.b);
    FitOptions o;
    o.shape = c.shape;
    const FitResult r = optimize_motion(surface, rails_from_trajectory(tr, o), o);
    MESSAGE((std::string(c.motion) + " " + c.profile_name) << ": " << tr.a.size() << " positions, eps_ini " << r.eps_ini.max
                     << " eps_opt " << r.eps_opt.max << " profile error " << profile_error_mm(r, ex, c.profile) << " mm");
    CHECK(r.eps_opt.max <= 1e-4);
  });
}

TEST_CASE("the machined envelope of a fit covers the exact envelope within the tolerance") {
  const Exact ex = exact_envelope("arc", cone_profile(6, 9));
  const SurfaceIndex surface(ex.unit_mesh);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.5, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
  FitOptions o;
  o.shape = ToolShape::Cone;
  const FitResult r = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
  const MachinedSurface ms = machined_surface(surface, r.rails, r.tool);
  CHECK(ms.omega.folded_triangles == 0);
  const double tol = ex.frame.length_to_unit(0.01);  // 10 µm
  const double cov = coverage(ex.unit_mesh, ms.design_deviation, tol);
  MESSAGE("coverage within 0.01 mm: " << cov);
  CHECK(cov > 0.8);
  // Sign: moving the whole design surface towards the tool makes it overcut (negative).
  TriMesh shifted = ex.unit_mesh;
  const auto normals = vertex_normals(ex.unit_mesh);
  for (size_t v = 0; v < shifted.vertices.size(); ++v) shifted.vertices[v] += ms.tool_side * tol * 5 * normals[v];
  const SurfaceIndex shifted_index(shifted);
  const MachinedSurface over = machined_surface(shifted_index, r.rails, r.tool);
  double mean = 0;
  int count = 0;
  for (double d : over.design_deviation)
    if (std::isfinite(d)) mean += d, ++count;
  CHECK(mean / count < -3 * tol);
}

namespace {
// Surface-driven fit on a (modified) copy of an exact envelope, from exact lines at t = 0, 0.5, 1.
FitResult fit_modified(const Exact& ex, const TriMesh& surface_mesh, ToolShape shape) {
  const SurfaceIndex surface(clean_mesh(surface_mesh, "test").mesh);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.5, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
  FitOptions o;
  o.shape = shape;
  return optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
}

// ε (eq. 13) of a fit measured against the clean, complete envelope: how far the tool found on the
// modified surface is from machining the true one (the motion itself is not unique, see w_anchor).
double eps_on(const SurfaceIndex& clean, const FitResult& r) { return sample_error(clean, r.rails, r.tool, {}).max; }
}  // namespace

TEST_CASE("noise of 1e-4 of the diagonal and two trimmed holes barely move the fitted motion") {
  const Exact ex = exact_envelope("arc", cone_profile(6, 9));
  const SurfaceIndex complete(ex.unit_mesh);

  TriMesh noisy = ex.unit_mesh;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1e-4, 1e-4);
  for (auto& v : noisy.vertices) v += Eigen::Vector3d(u(rng), u(rng), u(rng));
  const FitResult with_noise = fit_modified(ex, noisy, ToolShape::Cone);
  MESSAGE("noise: eps on the noisy mesh " << with_noise.eps_opt.max << ", on the clean envelope " << eps_on(complete, with_noise));
  CHECK(eps_on(complete, with_noise) < 3e-4);

  TriMesh holed = ex.unit_mesh;
  std::vector<std::array<int, 3>> kept;
  const Eigen::Vector3d h1 = ex.frame.to_unit(0.5 * (ex.motion.a(0.3) + ex.motion.b(0.3))),
                        h2 = ex.frame.to_unit(0.5 * (ex.motion.a(0.7) + ex.motion.b(0.7)));
  for (const auto& f : holed.faces) {
    const Eigen::Vector3d c = (holed.vertices[f[0]] + holed.vertices[f[1]] + holed.vertices[f[2]]) / 3;
    if ((c - h1).norm() < 0.09 || (c - h2).norm() < 0.07) continue;  // the axis is ~0.05 from Φ
    kept.push_back(f);
  }
  const size_t removed = holed.faces.size() - kept.size();
  holed.faces = kept;
  const FitResult with_holes = fit_modified(ex, holed, ToolShape::Cone);
  MESSAGE("holes: " << removed << " faces removed, eps " << with_holes.eps_opt.max << ", on the complete envelope "
                    << eps_on(complete, with_holes));
  CHECK(removed > 200);
  CHECK(with_holes.eps_opt.max <= 1e-4);
  CHECK(eps_on(complete, with_holes) < 1e-4);
}

TEST_CASE("a local bump on the design surface: the fit stays on the undisturbed part and coverage drops") {
  const Exact ex = exact_envelope("arc", cone_profile(6, 9));
  const SurfaceIndex clean(ex.unit_mesh);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.5, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
  // A smooth bump of 0.3% of the diagonal (about 0.4 mm) out of the material, in the middle of the sweep.
  const auto normals = vertex_normals(ex.unit_mesh);
  const Eigen::Vector3d c0 = clean.closest(0.5 * (lines[1].a + lines[1].b)).point;
  const double height = 0.003, sigma = 0.03;
  const int side = tool_side(clean, rails_from_lines(lines, 0, 0, FitOptions{}));
  TriMesh bumped = ex.unit_mesh;
  std::vector<char> disturbed(bumped.vertices.size(), 0);
  for (size_t v = 0; v < bumped.vertices.size(); ++v) {
    const double r = (ex.unit_mesh.vertices[v] - c0).norm();
    bumped.vertices[v] += side * height * std::exp(-0.5 * r * r / (sigma * sigma)) * normals[v];
    disturbed[v] = r < 3 * sigma;
  }
  const SurfaceIndex surface(bumped);
  const double tol = ex.frame.length_to_unit(0.01);  // 10 µm
  struct Outcome {
    double worst_outside, cov_clean, cov_bumped;
  };
  const auto fit = [&](double robust) {
    FitOptions o;
    o.shape = ToolShape::Cone;
    o.robust_scale = robust;
    const FitResult r = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
    const MachinedSurface on_clean = machined_surface(clean, r.rails, r.tool);
    const MachinedSurface on_bumped = machined_surface(surface, r.rails, r.tool);
    Outcome out{0, coverage(ex.unit_mesh, on_clean.design_deviation, tol), coverage(bumped, on_bumped.design_deviation, tol)};
    for (size_t v = 0; v < disturbed.size(); ++v)
      if (!disturbed[v] && std::isfinite(on_clean.design_deviation[v]))
        out.worst_outside = std::max(out.worst_outside, std::abs(on_clean.design_deviation[v]));
    MESSAGE("robust scale " << robust << ": worst deviation from the clean envelope outside the bump "
                            << ex.frame.length_to_mm(out.worst_outside) << " mm, coverage (10 µm) of the clean surface "
                            << out.cov_clean << ", of the bumped one " << out.cov_bumped);
    return out;
  };
  const Outcome robust = fit(1e-4), least_squares = fit(0.0);
  // With a Cauchy loss (job: fit: {robust: ...}) the machined surface stays on the clean envelope away from the bump ...
  CHECK(robust.worst_outside < ex.frame.length_to_unit(0.01));
  CHECK(robust.cov_clean > 0.95);
  // ... and the bump is left uncut, so coverage of the bumped design surface drops.
  CHECK(robust.cov_bumped < robust.cov_clean - 0.03);
  // Plain least squares (the paper, the default) is pulled towards the bump everywhere.
  CHECK(least_squares.worst_outside > 5 * robust.worst_outside);
}
