// The residuals of the motion fit (paper eqs. 9-12) as Ceres cost functions with hand-written
// Jacobians. Internal to core/fitting.cpp; a header only so that tests can check the Jacobians
// against numeric differentiation.
#pragma once
#include <ceres/ceres.h>

#include <Eigen/Core>
#include <cmath>
#include <utility>
#include <vector>

#include "core/bspline.h"

namespace flankcam::fit_residuals {

// r = sum_b J_b x_b - c: the plane, point and fairness residuals are linear in the
// unknowns once footpoints and normals are fixed (they are recomputed between solves).
class LinearResidual final : public ceres::CostFunction {
 public:
  LinearResidual(std::vector<Eigen::MatrixXd> J, Eigen::VectorXd c) : J_(std::move(J)), c_(std::move(c)) {
    set_num_residuals(int(c_.size()));
    for (const auto& j : J_) mutable_parameter_block_sizes()->push_back(int(j.cols()));
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const Eigen::Index n = c_.size();
    Eigen::Map<Eigen::VectorXd> r(residuals, n);
    r = -c_;
    for (size_t b = 0; b < J_.size(); ++b) {
      r += J_[b] * Eigen::Map<const Eigen::VectorXd>(x[b], J_[b].cols());
      if (jacobians && jacobians[b])
        Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(jacobians[b], n,
                                                                                            J_[b].cols()) = J_[b];
    }
    return true;
  }

 private:
  std::vector<Eigen::MatrixXd> J_;
  Eigen::VectorXd c_;
};

// One sample p_ij = (1-s) a(t_i) + s b(t_i) with its fixed footpoint q and unit normal n:
//   F_plane, eq. (10): w_plane (<p - q, n> - d_j)            (1 residual)
//   F_point, eq. (10): w_point (p - (q + d_j n))              (3 residuals)
// with a(t_i) = sum_k w_k A_k, b(t_i) = sum_k w_k B_k and d_j = sum_k c_k D_k.
class SampleResidual final : public ceres::CostFunction {
 public:
  SampleResidual(const BasisRow& row, double s, const Eigen::Vector3d& q, const Eigen::Vector3d& n,
                 const std::vector<double>& c, double w_plane, double w_point)
      : row_(row), s_(s), q_(q), n_(n), c_(c), w_plane_(w_plane), w_point_(w_point) {
    set_num_residuals(4);
    for (int k = 0; k < 8; ++k) mutable_parameter_block_sizes()->push_back(3);
    mutable_parameter_block_sizes()->push_back(int(c_.size()));
  }
  bool Evaluate(double const* const* x, double* r, double** J) const override {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
      p += row_.w[k] * ((1 - s_) * Eigen::Map<const Eigen::Vector3d>(x[k]) + s_ * Eigen::Map<const Eigen::Vector3d>(x[4 + k]));
    double d = 0;
    for (size_t k = 0; k < c_.size(); ++k) d += c_[k] * x[8][k];
    r[0] = w_plane_ * ((p - q_).dot(n_) - d);
    Eigen::Map<Eigen::Vector3d>{r + 1} = w_point_ * (p - q_ - d * n_);
    if (!J) return true;
    for (int k = 0; k < 8; ++k) {
      if (!J[k]) continue;
      const double f = row_.w[k % 4] * (k < 4 ? 1 - s_ : s_);
      Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> Jk(J[k]);
      Jk.row(0) = w_plane_ * f * n_.transpose();
      Jk.bottomRows<3>() = w_point_ * f * Eigen::Matrix3d::Identity();
    }
    if (J[8]) {
      const int K = int(c_.size());
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> Jd(J[8], 4, K);
      for (int k = 0; k < K; ++k) {
        Jd(0, k) = -w_plane_ * c_[size_t(k)];
        Jd.block<3, 1>(1, k) = -w_point_ * c_[size_t(k)] * n_;
      }
    }
    return true;
  }

 private:
  BasisRow row_;
  double s_;
  Eigen::Vector3d q_, n_;
  std::vector<double> c_;
  double w_plane_, w_point_;
};

// Rigidity, eq. (9) as a soft constraint: r = w (|a(t_i) - b(t_i)|^2 - L^2),
// a(t_i) = sum_k w_k A_k, b(t_i) = sum_k w_k B_k over the four active control points.
class RigidResidual final : public ceres::SizedCostFunction<1, 3, 3, 3, 3, 3, 3, 3, 3> {
 public:
  RigidResidual(const BasisRow& row, double L, double weight) : row_(row), L2_(L * L), w_(weight) {}
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
      u += row_.w[k] * (Eigen::Map<const Eigen::Vector3d>(x[k]) - Eigen::Map<const Eigen::Vector3d>(x[4 + k]));
    residuals[0] = w_ * (u.squaredNorm() - L2_);
    if (jacobians)
      for (int k = 0; k < 4; ++k) {
        if (jacobians[k]) Eigen::Map<Eigen::RowVector3d>{jacobians[k]} = 2 * w_ * row_.w[k] * u.transpose();
        if (jacobians[4 + k]) Eigen::Map<Eigen::RowVector3d>{jacobians[4 + k]} = -2 * w_ * row_.w[k] * u.transpose();
      }
    return true;
  }

 private:
  BasisRow row_;
  double L2_, w_;
};

// Tool constraints G D <= h (ToolConstraints) as one-sided penalties on the radius parameters:
//   r_k = w max(0, g_k . D - h_k)
// zero (and flat) where a row holds, linear in its violation where it does not.
class HingeResidual final : public ceres::CostFunction {
 public:
  HingeResidual(Eigen::MatrixXd G, Eigen::VectorXd h, double w) : G_(std::move(G)), h_(std::move(h)), w_(w) {
    set_num_residuals(int(h_.size()));
    mutable_parameter_block_sizes()->push_back(int(G_.cols()));
  }
  bool Evaluate(double const* const* x, double* residuals, double** jacobians) const override {
    const Eigen::VectorXd g = G_ * Eigen::Map<const Eigen::VectorXd>(x[0], G_.cols()) - h_;
    using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    for (Eigen::Index k = 0; k < g.size(); ++k) {
      const bool on = g[k] > 0;
      residuals[k] = on ? w_ * g[k] : 0.0;
      if (jacobians && jacobians[0])
        Eigen::Map<RowMajor>(jacobians[0], g.size(), G_.cols()).row(k) = on ? Eigen::RowVectorXd(w_ * G_.row(k))
                                                                            : Eigen::RowVectorXd::Zero(G_.cols());
    }
    return true;
  }

 private:
  Eigen::MatrixXd G_;
  Eigen::VectorXd h_;
  double w_;
};

// A check-surface sample (FitOptions::check): the axis point p = (1-s) a(t_i) + s b(t_i) (s outside
// [0, 1] on the shank and holder) must keep its signed distance <p - q, g> to the part (footpoint
// q, outward direction g, fixed within a solve) at least R, where R = d_j - tolerance for the cutter
// (c: d's basis at s, radius parameters as a 9th block) or a constant (c empty: shank, holder plus
// the clearance). One-sided: r = w max(0, R - <p - q, g>), zero and flat where it holds.
// `exactly`: two-sided, <p - q, g> pulled to R (a floor's pull on the tip, CheckSurface::floor_reach).
class CheckResidual final : public ceres::CostFunction {
 public:
  CheckResidual(const BasisRow& row, double s, const Eigen::Vector3d& q, const Eigen::Vector3d& g, std::vector<double> c,
                double offset, double w, bool exactly = false)
      : row_(row), s_(s), q_(q), g_(g), c_(std::move(c)), offset_(offset), w_(w), exactly_(exactly) {
    set_num_residuals(1);
    for (int k = 0; k < 8; ++k) mutable_parameter_block_sizes()->push_back(3);
    if (!c_.empty()) mutable_parameter_block_sizes()->push_back(int(c_.size()));
  }
  bool Evaluate(double const* const* x, double* r, double** J) const override {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k)
      p += row_.w[k] * ((1 - s_) * Eigen::Map<const Eigen::Vector3d>(x[k]) + s_ * Eigen::Map<const Eigen::Vector3d>(x[4 + k]));
    double R = offset_;
    for (size_t k = 0; k < c_.size(); ++k) R += c_[k] * x[8][k];
    const double v = R - (p - q_).dot(g_);
    const bool on = exactly_ || v > 0;
    r[0] = on ? w_ * v : 0.0;
    if (!J) return true;
    for (int k = 0; k < 8; ++k) {
      if (!J[k]) continue;
      const double f = row_.w[k % 4] * (k < 4 ? 1 - s_ : s_);
      Eigen::Map<Eigen::RowVector3d>{J[k]} = on ? Eigen::RowVector3d(-w_ * f * g_.transpose()) : Eigen::RowVector3d::Zero();
    }
    if (!c_.empty() && J[8])
      for (size_t k = 0; k < c_.size(); ++k) J[8][k] = on ? w_ * c_[k] : 0.0;
    return true;
  }

 private:
  BasisRow row_;
  double s_;
  Eigen::Vector3d q_, g_;
  std::vector<double> c_;
  double offset_, w_;
  bool exactly_;
};

// A solve whose result cannot be used: Ceres' FAILURE or USER_FAILURE, or a cost that is not
// finite. NO_CONVERGENCE only means the solve used its iteration budget.
inline bool solve_failed(const ceres::Solver::Summary& s) {
  return s.termination_type == ceres::FAILURE || s.termination_type == ceres::USER_FAILURE ||
         !std::isfinite(s.initial_cost) || !std::isfinite(s.final_cost);
}

}  // namespace flankcam::fit_residuals
