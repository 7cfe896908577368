#include "core/fitting.h"

// Ceres brings glog, whose CHECK macros would silently replace doctest's: include it first and
// drop them before doctest defines its own.
#include "core/fitting_residuals.h"
#undef CHECK
#undef CHECK_EQ
#undef CHECK_NE
#undef CHECK_LT
#undef CHECK_LE
#undef CHECK_GT
#undef CHECK_GE

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <functional>
#include <limits>
#include <random>

#include "core/errors.h"
#include "core/collision.h"
#include "core/machined_surface.h"
#include "core/patch.h"
#include "core/tool_end.h"
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

TEST_CASE("surface-driven fits of exact envelopes reach eps <= 1e-4 for every tool shape" * doctest::test_suite("heavy")) {
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
                     << " profile error " << profile_error_mm(r, ex, c.profile) << " mm, " << r.iterations << " iterations, " << std::string(to_string(r.status)));
    CHECK(r.eps_ini.max > 1e-3);
    CHECK(r.eps_opt.max <= 1e-4);
    CHECK(r.eps_opt.samples > 2000);
    // The radius is only weakly determined on nearly developable envelopes (see FitOptions::w_anchor):
    // it comes back within the 1% (1.3-1.6 mm) the lines were perturbed by.
    CHECK(profile_error_mm(r, ex, c.profile) < 1.2);
  });
}

TEST_CASE("line-driven fits from one perturbed line reach eps <= 1e-4" * doctest::test_suite("heavy")) {
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
                     << " eps_opt " << r.eps_opt.max << " profile error " << profile_error_mm(r, ex, c.profile) << " mm, " << r.iterations << " iterations, " << std::string(to_string(r.status)));
    CHECK(r.eps_opt.max <= 1e-4);
  });
}

TEST_CASE("the machined envelope of a fit covers the exact envelope within the tolerance" * doctest::test_suite("heavy")) {
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

TEST_CASE("noise of 1e-4 of the diagonal and two trimmed holes barely move the fitted motion" * doctest::test_suite("heavy")) {
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

TEST_CASE("a local bump on the design surface: the fit stays on the undisturbed part and coverage drops" * doctest::test_suite("heavy")) {
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

namespace {
// Worst relative difference between a cost function's Jacobians and central differences of its
// residuals at x (each block's columns; relative to the larger of the two and 1e-3 of the scale).
double jacobian_error(const ceres::CostFunction& f, std::vector<std::vector<double>> x) {
  const int nr = f.num_residuals();
  const auto& sizes = f.parameter_block_sizes();
  std::vector<const double*> xp;
  for (const auto& b : x) xp.push_back(b.data());
  std::vector<std::vector<double>> J;
  std::vector<double*> Jp;
  for (int s : sizes) J.emplace_back(size_t(nr * s)), Jp.push_back(J.back().data());
  std::vector<double> r(static_cast<size_t>(nr)), rp(static_cast<size_t>(nr)), rm(static_cast<size_t>(nr));
  REQUIRE(f.Evaluate(xp.data(), r.data(), Jp.data()));
  double worst = 0, scale = 0;
  for (const auto& Jb : J)
    for (double v : Jb) scale = std::max(scale, std::abs(v));
  for (size_t b = 0; b < x.size(); ++b)
    for (int c = 0; c < sizes[b]; ++c) {
      const double x0 = x[b][size_t(c)], h = 1e-6 * (1 + std::abs(x0));
      x[b][size_t(c)] = x0 + h;
      REQUIRE(f.Evaluate(xp.data(), rp.data(), nullptr));
      x[b][size_t(c)] = x0 - h;
      REQUIRE(f.Evaluate(xp.data(), rm.data(), nullptr));
      x[b][size_t(c)] = x0;
      for (int i = 0; i < nr; ++i) {
        const double numeric = (rp[size_t(i)] - rm[size_t(i)]) / (2 * h), analytic = J[b][size_t(i * sizes[b] + c)];
        worst = std::max(worst, std::abs(numeric - analytic) / std::max({std::abs(numeric), std::abs(analytic), 1e-3 * scale}));
      }
    }
  return worst;
}
}  // namespace

TEST_CASE("the hand-written Jacobians of the fit residuals agree with central differences at random points") {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1, 1), pos(0, 1);
  const auto random_block = [&](int n) {
    std::vector<double> b(static_cast<size_t>(n));
    for (auto& v : b) v = u(rng);
    return b;
  };
  for (int trial = 0; trial < 20; ++trial) {
    CAPTURE(trial);
    const BasisRow row = bspline_basis(16, pos(rng));
    const int K = trial % 3 == 0 ? 10 : trial % 3 == 1 ? 2 : 1;  // general, cone, cylinder radii
    std::vector<double> c(static_cast<size_t>(K));
    for (auto& v : c) v = pos(rng);
    const Eigen::Vector3d q(u(rng), u(rng), u(rng)), n = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    std::vector<std::vector<double>> x;
    for (int k = 0; k < 8; ++k) x.push_back(random_block(3));
    const fit_residuals::RigidResidual rigid(row, 0.3 + pos(rng), 0.7);
    CHECK(jacobian_error(rigid, x) < 1e-6);
    x.push_back(random_block(K));
    const fit_residuals::SampleResidual sample(row, pos(rng), q, n, c, 0.02, 0.001);
    CHECK(jacobian_error(sample, x) < 1e-6);
    const fit_residuals::LinearResidual linear({Eigen::MatrixXd::Random(3, 3), Eigen::MatrixXd::Random(3, K)},
                                               Eigen::VectorXd::Random(3));
    CHECK(jacobian_error(linear, {random_block(3), random_block(K)}) < 1e-6);
  }
}

TEST_CASE("a fit reports its status: converged, iteration limit, or a solver failure" * doctest::test_suite("heavy")) {
  const Exact ex = exact_envelope("arc", cone_profile(6, 9));
  const SurfaceIndex surface(ex.unit_mesh);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.5, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
  FitOptions o;
  o.shape = ToolShape::Cone;
  o.max_iterations = 1;
  o.stall = 0;
  o.motion_tolerance = 0;
  const FitResult capped = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
  CHECK(capped.status == FitStatus::IterationLimit);
  CHECK_FALSE(capped.converged);
  CHECK(capped.iterations == 1);
  o.max_iterations = 25;
  o.stall = 2e-2;
  const FitResult done = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
  CHECK(done.status == FitStatus::Converged);
  CHECK(done.converged);
  CHECK(done.message.empty());
  // What counts as a failed solve (then the fit stops, keeps the last good motion and says why).
  ceres::Solver::Summary summary;
  summary.initial_cost = 1, summary.final_cost = 0.5;
  for (auto [type, failed] : std::vector<std::pair<ceres::TerminationType, bool>>{
           {ceres::CONVERGENCE, false}, {ceres::NO_CONVERGENCE, false}, {ceres::FAILURE, true}, {ceres::USER_FAILURE, true}}) {
    summary.termination_type = type;
    CHECK(fit_residuals::solve_failed(summary) == failed);
  }
  summary.termination_type = ceres::CONVERGENCE;
  summary.final_cost = std::numeric_limits<double>::quiet_NaN();
  CHECK(fit_residuals::solve_failed(summary));
}

TEST_CASE("the plateau rule stops a fit whose rounds lower none of F, eps and the mean error, and no other") {
  // F_motion at fresh footpoints, eps and mean error before each round of fit_bench's 1M-vertex fit (in
  // units of 1e-12, 1e-6, 1e-7): from round 9 on the motion's ends slid along the rim, F sawed up and
  // down as samples came back over it, eps and the mean error flattened and then grew.
  const std::vector<RoundMeasures> slide = {
      {3.39e6, 9482.8, 18557}, {9.87, 13.743, 23.156}, {6.04, 8.4566, 14.148}, {5.02, 6.3316, 11.110},
      {5.79, 5.2342, 9.6525},  {5.22, 4.9141, 8.8888}, {4.76, 4.7953, 8.4634}, {4.39, 4.6905, 8.2067},
      {6.55, 4.6309, 8.0534},  {5.92, 4.6102, 7.9844}, {5.40, 4.5814, 7.9585}, {4.96, 4.5511, 7.9582},
      {5.89, 4.5202, 7.9691},  {5.31, 4.5525, 8.0085}, {4.84, 4.6775, 8.0539}, {5.77, 4.7910, 8.0981}};
  int stop = -1;
  for (size_t k = 1; k <= slide.size() && stop < 0; ++k)
    if (fit_plateaued(std::vector<RoundMeasures>(slide.begin(), slide.begin() + std::ptrdiff_t(k)), 1e-2, 3)) stop = int(k);
  // Round 13's eps is 1.3% below the best of rounds 1-11 (progress in rounds 12-14), none in rounds 13-15.
  CHECK(stop == 15);
  // Each measure alone keeps a fit going while it falls by more than the share within the window.
  for (int measure = 0; measure < 3; ++measure) {
    CAPTURE(measure);
    std::vector<RoundMeasures> h;
    for (int r = 0; r < 25; ++r) {
      RoundMeasures x{5 + 0.5 * (r % 3), 4.6, 8.0};  // F saws, eps and mean are flat
      double* falling[] = {&x.objective, &x.eps, &x.mean_error};
      *falling[measure] = 10 * std::pow(0.995, r);    // 1.5% in 3 rounds
      h.push_back(x);
      CHECK_FALSE(fit_plateaued(h, 1e-2, 3));
    }
    CHECK(fit_plateaued(h, 2e-2, 3));  // not by 2% in 3 rounds
  }
  // Not before `rounds` + 1 rounds; 0 rounds disables the rule.
  const std::vector<RoundMeasures> flat(4, RoundMeasures{1, 1, 1});
  CHECK_FALSE(fit_plateaued({flat.begin(), flat.begin() + 3}, 1e-2, 3));
  CHECK(fit_plateaued(flat, 1e-2, 3));
  CHECK(fit_plateaued(flat, 0, 3));
  CHECK_FALSE(fit_plateaued(flat, 1e-2, 0));
  FitOptions o;
  o.plateau = 1;
  CHECK(o.validate() == "plateau: must be in [0, 1)");
  o.plateau = 1e-2;
  o.plateau_rounds = -1;
  CHECK(o.validate() == "plateau_rounds: must be >= 0");
}

TEST_CASE("line-driven initialisation from a line with a 1e308 coordinate ends in an InputError, not a crash") {
  // Issue 12, item 1: the closest-point search read faces[-1] for such points.
  const Exact ex = exact_envelope("arc", cone_profile(6, 9));
  const SurfaceIndex surface(ex.unit_mesh);
  const Eigen::Vector3d a(1e308, 0.1, 0.2), b(0.0, 0.1, 0.3);
  const ExploredLine best = explore_line(surface, a, b);
  const LineTrajectory tr = propagate_line(surface, best.a, best.b);
  CHECK_THROWS_AS((void)rails_from_trajectory(tr, FitOptions{}), InputError);
}

TEST_CASE("a fit gives the same rails, radii and errors on 1 and 2 threads") {
  const Exact ex = exact_envelope("twist", barrel_profile(6, 1.5));
  const SurfaceIndex surface(ex.unit_mesh);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.5, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
  FitOptions o;
  o.max_iterations = 4;
  o.threads = 1;
  const FitResult one = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
  o.threads = 2;
  const FitResult two = optimize_motion(surface, rails_from_lines(lines, 0, 0, o), o);
  CHECK(one.rails.a.ctrl == two.rails.a.ctrl);
  CHECK(one.rails.b.ctrl == two.rails.b.ctrl);
  CHECK(one.tool.D == two.tool.D);
  CHECK(one.eps_opt.max == two.eps_opt.max);
  CHECK(one.objective == two.objective);
}

namespace {
// The tool's meridian in mm and what a tool grinder would measure on it.
struct MeridianFacts {
  double r_min = INFINITY, r_max = 0, r_tip = 0, length = 0, steepest_deg = 0, waist = 0;
};
MeridianFacts facts_mm(const FitResult& r, const Similarity& frame) {
  std::vector<Eigen::Vector2d> mer = meridian(r.tool, r.rails.length, 241);
  for (auto& p : mer) p = Eigen::Vector2d(frame.length_to_mm(p.x()), frame.length_to_mm(p.y()));
  MeridianFacts f;
  for (const auto& p : mer) f.r_min = std::min(f.r_min, p.y()), f.r_max = std::max(f.r_max, p.y());
  f.r_tip = mer.front().y();
  f.length = mer.back().x() - std::min(0.0, mer.front().x());
  for (size_t i = 1; i < mer.size(); ++i)
    f.steepest_deg = std::max(f.steepest_deg, std::atan2(std::abs(mer[i].y() - mer[i - 1].y()), mer[i].x() - mer[i - 1].x()) * 180 / M_PI);
  for (size_t j = 1; j + 1 < mer.size(); ++j) {  // a waist: lower than the highest points on both sides
    double left = 0, right = 0;
    for (size_t i = 0; i < j; ++i) left = std::max(left, mer[i].y());
    for (size_t i = j + 1; i < mer.size(); ++i) right = std::max(right, mer[i].y());
    f.waist = std::max(f.waist, std::min(left, right) - mer[j].y());
  }
  return f;
}
}  // namespace

TEST_CASE("tool constraints are met by every fitted tool where the unconstrained fit violates them" * doctest::test_suite("heavy")) {
  struct Limits {
    double min_d, max_d, max_len, min_tip, max_angle_deg;
    bool convex;
  };
  struct ConstrainedCase {
    const char* motion;
    const char* name;
    RadiusProfile profile;
    Limits limits;
  };
  // barrel: diameters 12 .. 15 mm, length 40, end slopes 8.5 deg; spline: a waist, diameters 10 .. 17 mm.
  const std::vector<ConstrainedCase> cases = {
      {"twist", "barrel", barrel_profile(6, 1.5), {11, 14, 35, 12.5, 5, false}},
      {"arc", "spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5}), {11, 15.5, 38, 10.5, 20, true}}};
  for (const ConstrainedCase& c : cases) {
    const std::string name = c.name;
    CAPTURE(name);
    const Exact ex = exact_envelope(c.motion, c.profile);
    const SurfaceIndex surface(ex.unit_mesh);
    std::vector<AxisLine> lines;
    for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) lines.push_back({ex.frame.to_unit(ex.motion.a(t)), ex.frame.to_unit(ex.motion.b(t))});
    FitOptions o;
    const Rails init = rails_from_lines(lines, 0, 0, o);
    const FitResult free_fit = optimize_motion(surface, init, o);
    const Limits& l = c.limits;
    ToolConstraints& tc = o.constraints;
    tc.min_radius = ex.frame.length_to_unit(l.min_d / 2);
    tc.max_radius = ex.frame.length_to_unit(l.max_d / 2);
    tc.max_length = ex.frame.length_to_unit(l.max_len);
    tc.min_tip_radius = ex.frame.length_to_unit(l.min_tip / 2);
    tc.max_cone_angle_rad = l.max_angle_deg * M_PI / 180;
    tc.convex = l.convex;
    const FitResult fit = optimize_motion(surface, init, o);
    const MeridianFacts before = facts_mm(free_fit, ex.frame), after = facts_mm(fit, ex.frame);
    const double tol = 1e-4;  // of the diagonal
    const MachinedSurface ms_free = machined_surface(surface, free_fit.rails, free_fit.tool);
    const MachinedSurface ms = machined_surface(surface, fit.rails, fit.tool);
    const double cov_free = coverage(ex.unit_mesh, ms_free.design_deviation, 10 * tol);
    const double cov = coverage(ex.unit_mesh, ms.design_deviation, 10 * tol);
    MESSAGE(name << ": free D " << 2 * before.r_min << ".." << 2 * before.r_max << " tip " << 2 * before.r_tip << " L "
                   << before.length << " angle " << before.steepest_deg << " waist " << before.waist << " | constrained D "
                   << 2 * after.r_min << ".." << 2 * after.r_max << " tip " << 2 * after.r_tip << " L " << after.length
                   << " angle " << after.steepest_deg << " waist " << after.waist << " | eps " << free_fit.eps_opt.max << " -> "
                   << fit.eps_opt.max << ", coverage within 1e-3 " << cov_free << " -> " << cov);
    // The unconstrained fit breaks the limits the test sets...
    CHECK(2 * before.r_max > l.max_d);
    CHECK(before.length > l.max_len);
    if (l.convex) CHECK(before.waist > 0.05);
    else CHECK(before.steepest_deg > l.max_angle_deg);
    if (c.name == std::string("barrel")) CHECK(2 * before.r_tip < l.min_tip);
    else CHECK(2 * before.r_min < l.min_d);
    // ... and the constrained one meets every one of them on its meridian (1 nm of slack).
    CHECK(2 * after.r_min >= l.min_d - 1e-6);
    CHECK(2 * after.r_max <= l.max_d + 1e-6);
    CHECK(2 * after.r_tip >= l.min_tip - 1e-6);
    CHECK(after.length <= l.max_len + 1e-6);
    CHECK(after.steepest_deg <= l.max_angle_deg + 1e-6);
    if (l.convex) CHECK(after.waist <= 1e-6);
    // Met as the report judges it: no violation beyond kConstraintSlack, nothing named.
    const ConstraintCheck cc = check_constraints(fit.tool, fit.rails.length, tc);
    CHECK(cc.violation == 0);
    CHECK(cc.what.empty());
    // It still fits and reports: a finite ε over the samples, part of the surface within the tolerance.
    CHECK(fit.eps_opt.samples > 1000);
    CHECK(std::isfinite(fit.eps_opt.max));
    CHECK(fit.status != FitStatus::SolverFailed);
    CHECK(cov > 0.1);
  }
}

TEST_CASE("tool_defect finds radii that describe no tool, and such a fit is not machinable") {
  const auto general = [](std::vector<double> D) {
    ToolRadius t;
    t.D = std::move(D);
    return t;
  };
  ToolRadius cone;
  cone.shape = ToolShape::Cone;
  cone.D = {0.05, 0.15};
  CHECK_FALSE(tool_defect(cone, 0.3));                                   // slope 1/3
  CHECK_FALSE(tool_defect(general({0.1, 0.12, 0.13, 0.12, 0.1}), 0.3));  // a barrel
  cone.D = {0.05, 0.5};                                                  // slope 1.5: the circles nest
  const std::optional<ToolDefect> steep = tool_defect(cone, 0.3);
  REQUIRE(steep);
  CHECK(steep->what.find("faster than its length") != std::string::npos);
  CHECK(steep->s == 0.0);
  // A radius through zero: found where it first reaches it; the collision check's own assembly of
  // the same radii (61 samples, as the pipeline builds it) refuses them too.
  const ToolRadius zero = general({0.1, 0.05, -0.05, 0.05, 0.1});
  const std::optional<ToolDefect> z = tool_defect(zero, 1.0);
  REQUIRE(z);
  CHECK(z->what == "its radius reaches 0");
  CHECK(zero.d(z->s) <= 0);
  CHECK(zero.d(z->s - 1.0 / 240) > 0);
  ToolAssembly a;
  for (int j = 0; j <= 60; ++j) a.cutter.emplace_back(1.0 * j / 60, zero.d(j / 60.0));
  CHECK(a.validate().find("radii must be positive") != std::string::npos);
  // A waist too deep for its length: the slope stays below 1 (0.75 at most) but the envelope of
  // the circles folds (z' = L - d d_ss / L < 0 at the middle).
  const std::optional<ToolDefect> fold = tool_defect(general({0.2, 0.15, 0.15, 0.2}), 0.2);
  REQUIRE(fold);
  CHECK(fold->what == "its meridian turns back on itself");
  CHECK_FALSE(tool_defect(general({0.2, 0.15, 0.15, 0.2}), 0.3));  // the same waist on a longer axis
  // A needle: more than 20 times as long as its largest diameter (the HECC diffuser's detection had
  // kept a Ø0.009 mm cylinder over 19.9 mm, and one of Ø0.89 mm).
  ToolRadius cylinder;
  cylinder.shape = ToolShape::Cylinder;
  cylinder.D = {0.01};
  CHECK_FALSE(tool_defect(cylinder, 0.39));  // 19.5 diameters
  const std::optional<ToolDefect> needle = tool_defect(cylinder, 0.41);
  REQUIRE(needle);
  CHECK(needle->what.find("20 times as long as its largest diameter") != std::string::npos);
  cone.D = {0.001, 0.02};  // a sharp taper is judged by its thick end
  CHECK_FALSE(tool_defect(cone, 0.79));
  CHECK(tool_defect(cone, 0.81));
  PatchFit f;
  f.fit.rails.length = 1.0;
  f.fit.tool = general({0.1, 0.12, 0.13, 0.12, 0.1});
  CHECK(machinable(f));
  f.fit.tool = zero;
  CHECK_FALSE(machinable(f));
}

TEST_CASE("a patch whose fitted radii describe no tool is refused by name before it is machined") {
  // A flat Φ 10 x 10 and a held tool whose waist folds its meridian (as in the test above): the fit
  // runs, and fit_patch refuses its radii instead of handing them to the tool end ("the tool's
  // meridian must have increasing z", naming no patch).
  const TriMesh phi_mesh = test::grid_mesh(11, 11, [](int i, int j) { return Eigen::Vector3d(i, j, 0); });
  const SurfaceIndex phi(phi_mesh);
  ToolRadius waist;
  waist.D = {0.2, 0.15, 0.15, 0.2};
  REQUIRE(tool_defect(waist, 0.2));
  PatchSpec spec;
  spec.name = "fold";
  for (double x : {2.0, 5.0, 8.0}) spec.lines.push_back({Eigen::Vector3d(x, 4, 0.2), Eigen::Vector3d(x, 4.2, 0.2)});
  PatchOptions po;
  po.tolerance = 1e-3;
  po.fit.fixed_tool = waist;
  try {
    (void)fit_patch(phi, spec, po);
    FAIL("fit_patch accepted a tool whose meridian folds");
  } catch (const InputError& e) {
    const std::string what = e.what();
    CHECK(what.rfind("patch 'fold': the fitted radii describe no tool: its meridian turns back on itself at ", 0) == 0);
    CHECK(what.find("set tool.min_diameter and tool.max_cone_angle") != std::string::npos);
  }
  // The same lines with a tool that is one (the waist on a longer axis) fit and machine.
  spec.length = 0.3;
  REQUIRE_FALSE(tool_defect(waist, 0.3));
  const PatchFit ok = fit_patch(phi, spec, po);
  CHECK(ok.fit.tool.D == waist.D);
  CHECK(std::abs(ok.fit.rails.length - 0.3) < 1e-12);
}

TEST_CASE("constrained_tool projects random radii onto every constraint row") {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.01, 0.2);
  for (int trial = 0; trial < 50; ++trial) {
    CAPTURE(trial);
    ToolRadius tool;
    tool.shape = trial % 3 == 0 ? ToolShape::Cone : ToolShape::General;
    tool.D.resize(tool.shape == ToolShape::Cone ? 2 : 10);
    for (double& d : tool.D) d = u(rng);
    ToolConstraints c;
    c.min_radius = 0.04, c.max_radius = 0.12, c.min_tip_radius = 0.05, c.max_cone_angle_rad = 0.1, c.convex = trial % 2 == 0;
    // A corner end on every fifth tool (its rows' axis points move with the projection: no fixed rows).
    if (trial % 5 == 1) c.min_ball_radius = 0.07, c.either_end = trial % 10 == 1;
    // A tip limit on every fourth but those (its bound scales with the radii: no fixed rows either;
    // a ball of 0.07 within 0.06 of the tip's width needs a steeper tool than the cone angle allows).
    if (trial % 4 == 2 && c.min_ball_radius == 0) c.max_tip_radius = 0.06, c.either_end = trial % 8 == 2;
    const ToolRadius p = constrained_tool(tool, 0.3, c);
    const Eigen::VectorXd D = Eigen::Map<const Eigen::VectorXd>(p.D.data(), Eigen::Index(p.D.size()));
    if (c.min_ball_radius == 0 && !std::isfinite(c.max_tip_radius)) {
      const ConstraintRows rows = constraint_rows(tool, 0.3, c);  // the rows the projection used
      CHECK((rows.G * D - rows.h).maxCoeff() <= 1e-12);
    }
    const ConstraintCheck cc = check_constraints(p, 0.3, c);
    CHECK(cc.violation == 0);
    CHECK(cc.what.empty());
  }
}

TEST_CASE("a corner end's radius and the tip's diameter limits are constraints of the fit, at both ends where asked") {
  // A cone narrowing away from its tip: d(0) = 0.1 above R = 0.095, yet its ball, d(0)(1 + sin a) with
  // sin a = -0.1, is 0.09: a bound on d(0) alone would let the corner not fit.
  const double L = 0.4, R = 0.095;
  ToolRadius cone;
  cone.shape = ToolShape::Cone;
  cone.D = {0.1, 0.06};
  CHECK(ball_radius(meridian(cone, L, 121)) == doctest::Approx(0.09).epsilon(1e-3));
  ToolConstraints c;
  c.min_ball_radius = R;
  ConstraintCheck cc = check_constraints(cone, L, c);
  CHECK(cc.what == "end.corner");
  CHECK(cc.violation == doctest::Approx(R - 0.09).epsilon(1e-2));
  ToolRadius held = constrained_tool(cone, L, c);
  CHECK(ball_radius(meridian(held, L, 121)) >= R);
  CHECK(ball_radius(meridian(held, L, 121)) < R * (1 + 2 * kBallMargin));  // the least change: on the bound
  CHECK(check_constraints(held, L, c).what.empty());
  // either_end: the wide end stays, the narrow end (0.06) is raised until its own ball is R.
  c.either_end = true;
  cc = check_constraints(held, L, c);
  CHECK(cc.what == "end.corner");
  held = constrained_tool(cone, L, c);
  std::vector<Eigen::Vector2d> turned;
  const std::vector<Eigen::Vector2d> mer = meridian(held, L, 121);
  for (auto p = mer.rbegin(); p != mer.rend(); ++p) turned.emplace_back(mer.back().x() - p->x(), p->y());
  CHECK(ball_radius(mer) >= R);
  CHECK(ball_radius(turned) >= R);
  CHECK(std::min(ball_radius(mer), ball_radius(turned)) < R * (1 + 2 * kBallMargin));
  CHECK(check_constraints(held, L, c).what.empty());
  // min_tip_radius at both ends too.
  ToolConstraints t;
  t.min_tip_radius = 0.08, t.either_end = true;
  CHECK(check_constraints(cone, L, t).what == "min_tip_diameter");
  const ToolRadius tipped = constrained_tool(cone, L, t);
  const std::vector<Eigen::Vector2d> tm = meridian(tipped, L, 121);
  CHECK(std::min(tm.front().y(), tm.back().y()) >= 0.08 - 1e-12);
  // max_tip_radius: the wide tip (0.1) is brought down to it, the other end (0.06) left. The cone
  // turned round meets it; at either end its wide end is brought down too.
  ToolConstraints mt;
  mt.max_tip_radius = 0.07;
  CHECK(check_constraints(cone, L, mt).what == "max_tip_diameter");
  const ToolRadius narrow = constrained_tool(cone, L, mt);
  CHECK(narrow.D[0] == doctest::Approx(0.07).epsilon(1e-9));
  CHECK(narrow.D[1] == doctest::Approx(0.06).epsilon(1e-9));
  CHECK(meridian(narrow, L, 121).front().y() <= 0.07);
  CHECK(check_constraints(narrow, L, mt).what.empty());
  ToolRadius turned_cone = cone;
  turned_cone.D = {0.06, 0.1};
  CHECK(check_constraints(turned_cone, L, mt).what.empty());
  mt.either_end = true;
  CHECK(check_constraints(turned_cone, L, mt).what == "max_tip_diameter");
  const ToolRadius both = constrained_tool(turned_cone, L, mt);
  CHECK(both.D[1] == doctest::Approx(0.07).epsilon(1e-9));
  CHECK(check_constraints(both, L, mt).what.empty());
  // A cone widening from its tip (0.06 to 0.1): ground, it ends in its tip plane, where the spheres
  // above the tip reach out to 0.06 / sqrt(1 - 0.1^2) = 0.0603 (cutter_union), not the meridian's
  // 0.0597. Held at 0.06 that is what is brought down to it, on the bound.
  ToolConstraints wt;
  wt.max_tip_radius = 0.06;
  CHECK(cutter_union(turned_cone, L, 2).front().y() == doctest::Approx(0.06 / std::sqrt(0.99)).epsilon(1e-6));
  CHECK(check_constraints(turned_cone, L, wt).what == "max_tip_diameter");
  const ToolRadius ground = constrained_tool(turned_cone, L, wt);
  const double ground_tip = cutter_union(ground, L, 2).front().y();
  MESSAGE("widening cone held at its tip: d ", ground.D[0], " .. ", ground.D[1], ", ground tip radius ", ground_tip);
  CHECK(ground_tip <= 0.06 + kConstraintSlack);
  CHECK(ground_tip > 0.06 * (1 - 1e-6));
  CHECK(check_constraints(ground, L, wt).what.empty());
  mt.min_tip_radius = 0.08;
  CHECK(mt.validate() == "tool.min_tip_diameter: larger than tool.max_tip_diameter");
  // A curved tool (a lens, its ball 2% short of R): held, the ball the run measures on its sampled
  // meridian (61 points, fit_stage) still takes R, and the rows at the result's own points hold.
  ToolRadius lens;
  lens.shape = ToolShape::General;
  for (int k = 0; k < 10; ++k) {
    const double s = k / 9.0;
    lens.D.push_back(0.04 + 0.06 * s - 0.06 * s * s);
  }
  const double lens_ball = ball_radius(meridian(lens, L, 2001));
  ToolConstraints lc;
  lc.min_ball_radius = 1.02 * lens_ball;
  CHECK(check_constraints(lens, L, lc).what == "end.corner");
  const ToolRadius held_lens = constrained_tool(lens, L, lc);
  CHECK(ball_radius(meridian(held_lens, L, 61)) >= lc.min_ball_radius);
  CHECK(ball_radius(meridian(held_lens, L, 2001)) < lc.min_ball_radius * (1 + 2 * kBallMargin));
  CHECK(check_constraints(held_lens, L, lc).what.empty());
  const ConstraintRows at_result = constraint_rows(held_lens, L, lc);
  const Eigen::VectorXd DL = Eigen::Map<const Eigen::VectorXd>(held_lens.D.data(), Eigen::Index(held_lens.D.size()));
  CHECK((at_result.G * DL - at_result.h).maxCoeff() <= 1e-12);
  // A corner larger than the largest radius allowed cannot be met: the limits say so.
  ToolConstraints bad;
  bad.min_ball_radius = 0.2, bad.max_radius = 0.15;
  CHECK(bad.validate() == "tool.end.corner: larger than half of tool.max_diameter");
}

TEST_CASE("a tool on its diameter bound meets it (rounding is no violation), one a hair over is named") {
  ToolConstraints c;
  c.max_radius = 0.1;
  ToolRadius cyl;
  cyl.shape = ToolShape::General;
  cyl.D.assign(5, 0.1);
  for (double& d : cyl.D) d = std::nextafter(0.1, 1.0);  // on the bound up to the last bit
  ConstraintCheck cc = check_constraints(cyl, 0.4, c);
  CHECK(cc.violation == 0);
  CHECK(cc.what.empty());  // the report's "met" and "violated" cannot disagree
  for (double& d : cyl.D) d = 0.1 + 1e-6;
  cc = check_constraints(cyl, 0.4, c);
  CHECK(cc.violation == doctest::Approx(1e-6).epsilon(1e-3));
  CHECK(cc.what == "max_diameter");
}

TEST_CASE("a fixed tool given by its meridian, fitted to its own exact envelope, is recovered by the motion alone" * doctest::test_suite("heavy")) {
  // A circle-segment (barrel) tool: Ø16 at the middle, profile radius 150 mm, 40 mm long.
  const ToolRadius mm_tool = test::catalogue_barrel_mm();
  // The sphere radii reproduce the meridian: d at the middle is the radius there, 8 mm.
  CHECK(std::abs(mm_tool.d(0.5) - 8) < 1e-3);
  const Exact ex = exact_envelope("arc", mm_tool.profile());
  const SurfaceIndex surface(ex.unit_mesh);
  std::mt19937 rng(3);
  std::vector<AxisLine> lines;
  for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) lines.push_back(perturbed(ex, t, rng));
  FitOptions o;
  ToolRadius unit_tool = mm_tool;
  for (double& d : unit_tool.D) d = ex.frame.length_to_unit(d);
  o.fixed_tool = unit_tool;
  const FitResult r = optimize_motion(surface, rails_from_lines(lines, 0, ex.frame.length_to_unit(40), o), o);
  CHECK(r.tool.D == unit_tool.D);  // the radii were not unknowns
  const MachinedSurface ms = machined_surface(surface, r.rails, r.tool);
  const double cov = coverage(ex.unit_mesh, ms.design_deviation, 1e-4);
  MESSAGE("fixed barrel tool: eps " << r.eps_ini.max << " -> " << r.eps_opt.max << ", coverage within 1e-4: " << cov);
  CHECK(cov >= 0.95);
  CHECK(r.eps_opt.max <= 1e-4);
}

TEST_CASE("a motion with no sample over the design surface: the fit stops with a reason, it does not abort") {
  // A flat Φ 10 x 10 (unit frame) and a tool standing 3 beside it: every sample's footpoint is on Φ's
  // rim, so no round has anything to fit (with the radii held, Ceres aborted on their absent block).
  const TriMesh phi_mesh = test::grid_mesh(11, 11, [](int i, int j) { return Eigen::Vector3d(i, j, 0); });
  const SurfaceIndex phi(phi_mesh);
  const int samples = 40;
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    A.row(i) = Eigen::RowVector3d(10 * ts[size_t(i)], 13, 0.5);
    B.row(i) = Eigen::RowVector3d(10 * ts[size_t(i)], 13, 4.5);
  }
  const int cps = FitOptions{}.rail_control_points;
  const Rails off{fit_bspline(A, ts, cps), fit_bspline(B, ts, cps), 4};
  ToolRadius cylinder;
  cylinder.shape = ToolShape::Cylinder;
  cylinder.D = {1.0};
  // Radii free: refused up front (the meridian update has no distances to start from).
  CHECK_THROWS_WITH_AS(optimize_motion(phi, off, FitOptions{}),
                       "the initial motion is not over the design surface: almost all footpoints lie on its boundary",
                       InputError);
  // Radii held (a catalogue or shared tool): the rounds run and stop with the reason.
  FitOptions o;
  o.fixed_tool = cylinder;
  const FitResult fit = optimize_motion(phi, off, o);
  CHECK(fit.status == FitStatus::SolverFailed);
  CHECK(fit.message == "no sample of the motion lies over the design surface");
  // The motion it was given is kept, not a garbage one.
  for (double t : {0.0, 0.5, 1.0}) {
    CHECK((fit.rails.a.point(t) - off.a.point(t)).norm() < 1e-9);
    CHECK((fit.rails.b.point(t) - off.b.point(t)).norm() < 1e-9);
  }
}
