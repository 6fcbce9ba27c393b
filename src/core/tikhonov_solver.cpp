#include "errsep/core/tikhonov_solver.hpp"

#include <Eigen/CholmodSupport>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace errsep::core {
namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

const char* to_string(SolverStatus s) {
  switch (s) {
    case SolverStatus::success:
      return "success";
    case SolverStatus::not_positive_definite:
      return "not positive definite";
    case SolverStatus::analysis_failed:
      return "analysis failed";
    case SolverStatus::not_factorized:
      return "not factorized";
  }
  return "unknown";
}

struct TikhonovSolver::Impl {
  Eigen::SparseMatrix<double> AtA;
  Eigen::CholmodSimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower> ldlt;
  bool factor_ok = false;
};

TikhonovSolver::TikhonovSolver(const Eigen::SparseMatrix<double>& A)
    : impl_(std::make_unique<Impl>()), A_(A) {
  const auto t0 = std::chrono::steady_clock::now();
  // Forming AᵀA once is several times faster per λ than letting CHOLMOD form AAᵀ on every call.
  // (A.transpose() * A).pruned() goes through a SparseView assignment that is quadratic in N;
  // a materialised transpose and a plain sparse product are linear for a band.
  const Eigen::SparseMatrix<double> At = A_.transpose();
  impl_->AtA = At * A_;
  impl_->AtA.prune(0.0);
  impl_->AtA.makeCompressed();
  double norm1 = 0.0;  // ‖AᵀA‖₁ >= λ_max(AᵀA) = σ_max(A)²
  for (int c = 0; c < impl_->AtA.outerSize(); ++c) {
    double s = 0.0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(impl_->AtA, c); it; ++it)
      s += std::abs(it.value());
    norm1 = std::max(norm1, s);
  }
  sigma_max_bound_ = std::sqrt(norm1);

  // AᵀA is a band (half-width s2+s3+s4) plus 4 dense trailing rows (the Δe columns): natural
  // ordering keeps it fill-free and a simplicial factor beats a supernodal one for a band.
  cholmod_common& cm = impl_->ldlt.cholmod();
  cm.nmethods = 1;
  cm.method[0].ordering = CHOLMOD_NATURAL;
  cm.postorder = 0;
  impl_->ldlt.analyzePattern(impl_->AtA);
  if (impl_->ldlt.info() != Eigen::Success || cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD symbolic analysis failed (status " +
                             std::to_string(cm.status) + ")");
  stats_.analyze_s = seconds_since(t0);
}

TikhonovSolver::~TikhonovSolver() = default;

SolverStatus TikhonovSolver::factorize(double lambda) {
  const auto t0 = std::chrono::steady_clock::now();
  impl_->ldlt.setShift(lambda * lambda);  // cholmod_factorize_p with β = λ²
  impl_->ldlt.factorize(impl_->AtA);
  ++stats_.factorizations;
  stats_.factorize_s += seconds_since(t0);
  lambda_ = lambda;
  // Eigen maps CHOLMOD's L->minor < n to NumericalIssue; Common->status is checked as well since
  // cholmod_factorize returns TRUE even when it failed.
  impl_->factor_ok =
      impl_->ldlt.info() == Eigen::Success && impl_->ldlt.cholmod().status == CHOLMOD_OK;
  return impl_->factor_ok ? SolverStatus::success : SolverStatus::not_positive_definite;
}

Eigen::VectorXd TikhonovSolver::solve_normal(const Eigen::VectorXd& rhs) {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::solve_normal without a successful factorisation");
  const auto t0 = std::chrono::steady_clock::now();
  Eigen::VectorXd y = impl_->ldlt.solve(rhs);
  ++stats_.solves;
  stats_.solve_s += seconds_since(t0);
  return y;
}

Eigen::VectorXd TikhonovSolver::solve(const Eigen::VectorXd& b) {
  return solve_normal(A_.transpose() * b);
}

}  // namespace errsep::core
