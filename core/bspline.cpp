#include "core/bspline.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cassert>
#include <cmath>

#include "core/errors.h"

namespace flankcam {
namespace {

double knot(int n_ctrl, int i) {
  // Clamped uniform knot vector of length n_ctrl + 4.
  const int segments = n_ctrl - 3;
  return double(std::clamp(i - 3, 0, segments)) / segments;
}

}  // namespace

BasisRow bspline_basis(int n_ctrl, double t, int derivative) {
  if (n_ctrl < 4) throw InputError("a cubic B-spline needs at least 4 control points");
  if (derivative < 0 || derivative > 2) throw InputError("B-spline: derivative order must be 0, 1 or 2");
  // A NaN would pass the clamp and turn the span index into INT_MIN (an out-of-bounds write).
  if (!std::isfinite(t)) throw InputError(fmt::format("B-spline parameter is not finite ({}): a coordinate overflows", t));
  const int p = 3, segments = n_ctrl - 3;
  t = std::clamp(t, 0.0, 1.0);
  const int span = std::min(int(std::floor(t * segments)), segments - 1) + 3;  // knot span index

  // Derivatives of the basis functions (The NURBS Book, A2.3), up to order 2.
  double ndu[4][4], left[4], right[4];
  ndu[0][0] = 1.0;
  for (int j = 1; j <= p; ++j) {
    left[j] = t - knot(n_ctrl, span + 1 - j);
    right[j] = knot(n_ctrl, span + j) - t;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      ndu[j][r] = right[r + 1] + left[j - r];
      const double temp = ndu[r][j - 1] / ndu[j][r];
      ndu[r][j] = saved + right[r + 1] * temp;
      saved = left[j - r] * temp;
    }
    ndu[j][j] = saved;
  }
  BasisRow row;
  row.first = span - p;
  if (derivative == 0) {
    for (int j = 0; j <= p; ++j) row.w[j] = ndu[j][p];
    return row;
  }
  double a[2][4];
  double ders[3][4] = {};
  for (int r = 0; r <= p; ++r) {
    int s1 = 0, s2 = 1;
    a[0][0] = 1.0;
    for (int k = 1; k <= derivative; ++k) {
      double d = 0.0;
      const int rk = r - k, pk = p - k;
      if (r >= k) {
        a[s2][0] = a[s1][0] / ndu[pk + 1][rk];
        d = a[s2][0] * ndu[rk][pk];
      }
      const int j1 = rk >= -1 ? 1 : -rk;
      const int j2 = (r - 1 <= pk) ? k - 1 : p - r;
      for (int j = j1; j <= j2; ++j) {
        a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j];
        d += a[s2][j] * ndu[rk + j][pk];
      }
      if (r <= pk) {
        a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
        d += a[s2][k] * ndu[r][pk];
      }
      ders[k][r] = d;
      std::swap(s1, s2);
    }
  }
  const double factor = derivative == 1 ? p : p * (p - 1);
  for (int j = 0; j <= p; ++j) row.w[j] = ders[derivative][j] * factor;
  return row;
}

Eigen::MatrixXd bspline_basis_matrix(int n_ctrl, const std::vector<double>& ts, int derivative) {
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(Eigen::Index(ts.size()), n_ctrl);
  for (size_t i = 0; i < ts.size(); ++i) {
    const BasisRow r = bspline_basis(n_ctrl, ts[i], derivative);
    for (int k = 0; k < 4; ++k) B(Eigen::Index(i), r.first + k) = r.w[k];
  }
  return B;
}

Eigen::VectorXd BSpline::eval(double t, int derivative) const {
  const BasisRow r = bspline_basis(size(), t, derivative);
  Eigen::VectorXd out = Eigen::VectorXd::Zero(dim());
  for (int k = 0; k < 4; ++k) out += r.w[k] * ctrl.row(r.first + k).transpose();
  return out;
}

Eigen::Vector3d BSpline::point(double t, int derivative) const {
  assert(dim() == 3);
  const BasisRow r = bspline_basis(size(), t, derivative);
  Eigen::Vector3d out = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) out += r.w[k] * ctrl.row(r.first + k).transpose();
  return out;
}

double BSpline::value(double t, int derivative) const {
  assert(dim() == 1);
  const BasisRow r = bspline_basis(size(), t, derivative);
  double out = 0;
  for (int k = 0; k < 4; ++k) out += r.w[k] * ctrl(r.first + k, 0);
  return out;
}

BSpline fit_bspline(const Eigen::MatrixXd& points, const std::vector<double>& ts, int n_ctrl, double smoothness) {
  if (points.rows() != Eigen::Index(ts.size())) throw InputError("fit_bspline: one parameter per point is needed");
  if (n_ctrl < 4) throw InputError("fit_bspline: at least 4 control points");
  if (!points.allFinite()) throw InputError("fit_bspline: a point is not finite (a coordinate overflows)");
  const Eigen::MatrixXd B = bspline_basis_matrix(n_ctrl, ts, 0);
  Eigen::MatrixXd N = B.transpose() * B;
  if (smoothness > 0) {
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(n_ctrl - 2, n_ctrl);
    for (int i = 0; i + 2 < n_ctrl; ++i) D.row(i).segment(i, 3) << 1, -2, 1;
    N += smoothness * D.transpose() * D;
  }
  // A tiny ridge keeps control points of empty spans determined (they stay near neighbours).
  Eigen::MatrixXd ridge = Eigen::MatrixXd::Zero(n_ctrl - 1, n_ctrl);
  for (int i = 0; i + 1 < n_ctrl; ++i) ridge.row(i).segment(i, 2) << 1, -1;
  N += 1e-12 * N.trace() / n_ctrl * ridge.transpose() * ridge;
  BSpline s;
  s.ctrl = N.ldlt().solve(B.transpose() * points);
  return s;
}

std::vector<double> chord_length_parameters(const Eigen::MatrixXd& points) {
  const Eigen::Index m = points.rows();
  std::vector<double> t(size_t(m), 0.0);
  for (Eigen::Index i = 1; i < m; ++i) t[i] = t[i - 1] + (points.row(i) - points.row(i - 1)).norm();
  if (m > 0 && !std::isfinite(t.back()))
    throw InputError(fmt::format("chord length is not finite ({}): coordinates too large (beyond ~1e150 mm) or not numbers",
                                 t.back()));
  if (m < 2 || t.back() <= 0) return uniform_parameters(int(m));
  for (double& x : t) x /= t.back();
  return t;
}

std::vector<double> uniform_parameters(int count) {
  std::vector<double> t(size_t(std::max(count, 0)));
  for (int i = 0; i < count; ++i) t[i] = count > 1 ? double(i) / (count - 1) : 0.0;
  return t;
}

}  // namespace flankcam
