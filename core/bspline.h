// Clamped uniform cubic B-spline curves of any dimension (rows of `ctrl` are
// control points; 1D for meridians and radii, 3D for the axis rails a(t), b(t)).
// Parameter range [0, 1]; knots 0,0,0,0, 1/(N-3), ..., 1,1,1,1 for N control points.
#pragma once
#include <Eigen/Core>
#include <array>
#include <vector>

namespace flankcam {

// The four basis functions that do not vanish at t: weights of ctrl.row(first + k).
struct BasisRow {
  int first = 0;
  std::array<double, 4> w{};
};
// derivative = 0, 1 or 2 (with respect to t). Requires n_ctrl >= 4.
[[nodiscard]] BasisRow bspline_basis(int n_ctrl, double t, int derivative = 0);
// Dense m x n_ctrl matrix whose row i maps control points to the curve (or its derivative) at ts[i].
[[nodiscard]] Eigen::MatrixXd bspline_basis_matrix(int n_ctrl, const std::vector<double>& ts, int derivative = 0);

struct BSpline {
  Eigen::MatrixXd ctrl;  // n_ctrl x dim

  [[nodiscard]] int size() const { return int(ctrl.rows()); }
  [[nodiscard]] int dim() const { return int(ctrl.cols()); }
  [[nodiscard]] Eigen::VectorXd eval(double t, int derivative = 0) const;
  // Convenience for 3D curves and 1D functions.
  [[nodiscard]] Eigen::Vector3d point(double t, int derivative = 0) const;
  [[nodiscard]] double value(double t, int derivative = 0) const;
};

// Least squares: min |B C - P|^2 + smoothness * |D2 C|^2, where D2 takes second
// differences of consecutive control points (a discrete bending energy). Rows of P
// are points at parameters ts (increasing, in [0, 1]).
[[nodiscard]] BSpline fit_bspline(const Eigen::MatrixXd& points, const std::vector<double>& ts, int n_ctrl,
                                  double smoothness = 0.0);
// Parameters in [0, 1] proportional to accumulated chord length (uniform if all points coincide).
[[nodiscard]] std::vector<double> chord_length_parameters(const Eigen::MatrixXd& points);
[[nodiscard]] std::vector<double> uniform_parameters(int count);

}  // namespace flankcam
