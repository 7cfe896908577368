#include "core/bspline.h"

#include <doctest/doctest.h>

#include <cmath>
#include <random>

#include "core/errors.h"

using namespace flankcam;

namespace {
// A cubic polynomial and its derivatives; clamped cubic B-splines reproduce it exactly.
double poly(double t, int der) {
  switch (der) {
    case 0: return 2 - 3 * t + 5 * t * t - 4 * t * t * t;
    case 1: return -3 + 10 * t - 12 * t * t;
    default: return 10 - 24 * t;
  }
}
}  // namespace

TEST_CASE("the basis is a partition of unity and its derivatives sum to zero") {
  for (int n : {4, 5, 10, 23})
    for (double t : {0.0, 0.013, 0.25, 0.5, 0.77, 0.999, 1.0}) {
      CAPTURE(n);
      CAPTURE(t);
      for (int der = 0; der <= 2; ++der) {
        const BasisRow r = bspline_basis(n, t, der);
        CHECK(r.first >= 0);
        CHECK(r.first + 3 < n);
        const double sum = r.w[0] + r.w[1] + r.w[2] + r.w[3];
        CHECK(sum == doctest::Approx(der == 0 ? 1.0 : 0.0).epsilon(1e-12).scale(1.0));
      }
    }
}

TEST_CASE("least squares reproduces a cubic polynomial with its first and second derivatives") {
  for (int n_ctrl : {4, 7, 12}) {
    CAPTURE(n_ctrl);
    std::vector<double> ts;
    Eigen::MatrixXd pts(40, 1);
    for (int i = 0; i < 40; ++i) {
      ts.push_back(std::pow(i / 39.0, 1.3));  // non-uniform samples
      pts(i, 0) = poly(ts.back(), 0);
    }
    const BSpline s = fit_bspline(pts, ts, n_ctrl);
    for (double t = 0; t <= 1.0; t += 0.0625)
      for (int der = 0; der <= 2; ++der) CHECK(s.value(t, der) == doctest::Approx(poly(t, der)).epsilon(1e-9));
  }
}

TEST_CASE("3D fitting reproduces a cubic space curve and the basis matrix agrees with eval") {
  std::vector<double> ts;
  Eigen::MatrixXd pts(30, 3);
  for (int i = 0; i < 30; ++i) {
    const double t = i / 29.0;
    ts.push_back(t);
    pts.row(i) << poly(t, 0), t * t * t, 3 * t - 1;
  }
  const BSpline s = fit_bspline(pts, ts, 8);
  CHECK(s.dim() == 3);
  const Eigen::MatrixXd B1 = bspline_basis_matrix(8, ts, 1);
  const Eigen::MatrixXd d1 = B1 * s.ctrl;
  for (int i = 0; i < 30; ++i) {
    const double t = ts[i];
    CHECK((s.point(t) - pts.row(i).transpose()).norm() < 1e-10);
    CHECK((s.point(t, 1) - Eigen::Vector3d(poly(t, 1), 3 * t * t, 3)).norm() < 1e-8);
    CHECK((d1.row(i).transpose() - s.point(t, 1)).norm() < 1e-12);
  }
}

TEST_CASE("derivatives agree with finite differences on a random spline") {
  std::mt19937 rng(42);
  std::normal_distribution<double> g;
  BSpline s;
  s.ctrl = Eigen::MatrixXd::NullaryExpr(9, 2, [&]() { return g(rng); });
  const double h = 1e-6;
  for (double t : {0.05, 0.31, 0.47, 0.66, 0.94}) {  // off the knots k/6
    const Eigen::VectorXd fd1 = (s.eval(t + h) - s.eval(t - h)) / (2 * h);
    const Eigen::VectorXd fd2 = (s.eval(t + h, 1) - s.eval(t - h, 1)) / (2 * h);
    CHECK((fd1 - s.eval(t, 1)).norm() < 1e-6);
    CHECK((fd2 - s.eval(t, 2)).norm() < 1e-5);
  }
}

TEST_CASE("a smoothness weight trades fidelity for a smaller bending energy") {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.05);
  std::vector<double> ts;
  Eigen::MatrixXd pts(100, 1);
  for (int i = 0; i < 100; ++i) {
    ts.push_back(i / 99.0);
    pts(i, 0) = std::sin(3 * ts.back()) + noise(rng);
  }
  const auto bending = [](const BSpline& s) {
    double e = 0;
    for (int i = 0; i + 2 < s.size(); ++i) e += std::pow(s.ctrl(i, 0) - 2 * s.ctrl(i + 1, 0) + s.ctrl(i + 2, 0), 2);
    return e;
  };
  const BSpline rough = fit_bspline(pts, ts, 30, 0.0), smooth = fit_bspline(pts, ts, 30, 10.0);
  CHECK(bending(smooth) < 0.1 * bending(rough));
  double err = 0;
  for (int i = 0; i < 100; ++i) err = std::max(err, std::abs(smooth.value(ts[i]) - std::sin(3 * ts[i])));
  CHECK(err < 0.1);
}

TEST_CASE("chord-length parameters run from 0 to 1 in proportion to distance") {
  Eigen::MatrixXd pts(4, 2);
  pts << 0, 0, 1, 0, 1, 3, 1, 4;
  const auto t = chord_length_parameters(pts);
  CHECK(t[0] == 0.0);
  CHECK(t[1] == doctest::Approx(0.2));
  CHECK(t[2] == doctest::Approx(0.8));
  CHECK(t[3] == 1.0);
}

// Issue 12 item 1: a line coordinate of 1e308 overflowed the chord length, the NaN parameter made
// the span index INT_MIN and the basis matrix was written out of bounds.
TEST_CASE("non-finite parameters and overflowing chord lengths are input errors, not out-of-bounds writes") {
  const double nan = std::nan(""), inf = INFINITY;
  for (double t : {nan, inf, -inf}) {
    CAPTURE(t);
    CHECK_THROWS_AS((void)bspline_basis(6, t), InputError);
    CHECK_THROWS_AS((void)bspline_basis_matrix(6, {0.0, t, 1.0}), InputError);
  }
  Eigen::MatrixXd far(3, 3);
  far << 0, 0, 0, 1e308, 0, 0, -1e308, 0, 0;  // |p1 - p0| + |p2 - p1| = inf
  CHECK_THROWS_WITH_AS((void)chord_length_parameters(far), doctest::Contains("not finite"), InputError);
  Eigen::MatrixXd bad = Eigen::MatrixXd::Zero(5, 1);
  bad(2, 0) = nan;
  CHECK_THROWS_AS((void)fit_bspline(bad, uniform_parameters(5), 4), InputError);
  // Parameters outside [0, 1] are clamped: the ends of the curve, as before.
  const BasisRow lo = bspline_basis(6, -1e300), hi = bspline_basis(6, 1e300);
  CHECK(lo.first == 0);
  CHECK(lo.w[0] == doctest::Approx(1));
  CHECK(hi.first == 2);
  CHECK(hi.w[3] == doctest::Approx(1));
}
