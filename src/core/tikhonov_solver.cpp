#include "errsep/core/tikhonov_solver.hpp"

#include <cholmod.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace errsep::core {
namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// A CHOLMOD workspace set up for a banded normal matrix: natural ordering (AᵀA is a band plus a
// few dense trailing rows, already in a fill-free order), no postordering, simplicial LDLᵀ (a
// supernodal factor is 3x slower on a narrow band: its supernodes are tiny).
void start_common(cholmod_common& cm) {
  cholmod_start(&cm);
  cm.nmethods = 1;
  cm.method[0].ordering = CHOLMOD_NATURAL;
  cm.postorder = 0;
  cm.supernodal = CHOLMOD_SIMPLICIAL;
  cm.final_ll = 0;
  cm.print = 0;
  cm.error_handler = nullptr;  // status is checked after every call
}

// Views an Eigen column-major sparse matrix as an unsymmetric cholmod_sparse (no copy).
cholmod_sparse view(const Eigen::SparseMatrix<double>& M) {
  cholmod_sparse s{};
  s.nrow = static_cast<size_t>(M.rows());
  s.ncol = static_cast<size_t>(M.cols());
  s.nzmax = static_cast<size_t>(M.nonZeros());
  s.p = const_cast<int*>(M.outerIndexPtr());
  s.i = const_cast<int*>(M.innerIndexPtr());
  s.x = const_cast<double*>(M.valuePtr());
  s.stype = 0;
  s.itype = CHOLMOD_INT;
  s.xtype = CHOLMOD_REAL;
  s.dtype = CHOLMOD_DOUBLE;
  s.sorted = 1;
  s.packed = 1;
  return s;
}

cholmod_dense view(const Eigen::VectorXd& v) {
  cholmod_dense d{};
  d.nrow = d.nzmax = d.d = static_cast<size_t>(v.size());
  d.ncol = 1;
  d.x = const_cast<double*>(v.data());
  d.xtype = CHOLMOD_REAL;
  d.dtype = CHOLMOD_DOUBLE;
  return d;
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

// The upper triangle of AᵀA (stype = 1: CHOLMOD's up-looking simplicial factorisation reads it
// as it is; a lower-stored matrix would be transposed on every factorisation, 30% of its time).
// Read-only once built, so workers on other threads share it.
struct TikhonovSolver::Normal {
  cholmod_common cm{};
  cholmod_sparse* upper = nullptr;
  Normal() { start_common(cm); }
  ~Normal() {
    cholmod_free_sparse(&upper, &cm);
    cholmod_finish(&cm);
  }
  Normal(const Normal&) = delete;
  Normal& operator=(const Normal&) = delete;
};

struct TikhonovSolver::Impl {
  cholmod_common cm{};
  cholmod_factor* L = nullptr;
  // Solution and workspace of cholmod_solve2, kept between solves: a fresh 8 MB vector per solve
  // at N = 10⁶ costs page faults comparable to the solve itself.
  cholmod_dense *X = nullptr, *Y = nullptr, *E = nullptr;
  bool factor_ok = false;
  Impl() { start_common(cm); }
  ~Impl() {
    cholmod_free_dense(&X, &cm);
    cholmod_free_dense(&Y, &cm);
    cholmod_free_dense(&E, &cm);
    cholmod_free_factor(&L, &cm);
    cholmod_finish(&cm);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
};

TikhonovSolver::TikhonovSolver(const Eigen::SparseMatrix<double>& A)
    : A_(std::make_shared<const Eigen::SparseMatrix<double>>(A)),
      normal_(std::make_shared<Normal>()),
      impl_(std::make_unique<Impl>()) {
  const auto t0 = std::chrono::steady_clock::now();
  cholmod_common& cm = normal_->cm;
  // AᵀA = F·Fᵀ with F = Aᵀ (cholmod_aat; 3x faster than Eigen's sparse-sparse product here).
  Eigen::SparseMatrix<double> At = A_->transpose();
  At.makeCompressed();
  cholmod_sparse F = view(At);
  cholmod_sparse* full = cholmod_aat(&F, nullptr, 0, 1, &cm);
  if (!full || cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD could not form AᵀA (status " + std::to_string(cm.status) +
                             ")");
  At = Eigen::SparseMatrix<double>();  // free before the next copy
  double norm1 = 0.0, max_abs = 0.0;   // ‖AᵀA‖₁ >= λ_max(AᵀA) = σ_max(A)²
  {
    const auto* p = static_cast<const int*>(full->p);
    const auto* x = static_cast<const double*>(full->x);
    for (size_t c = 0; c < full->ncol; ++c) {
      double s = 0.0;
      for (int k = p[c]; k < p[c + 1]; ++k) {
        s += std::abs(x[k]);
        max_abs = std::max(max_abs, std::abs(x[k]));
      }
      norm1 = std::max(norm1, s);
    }
  }
  sigma_max_bound_ = std::sqrt(norm1);
  normal_->upper = cholmod_copy(full, 1, 1, &cm);
  cholmod_free_sparse(&full, &cm);
  if (!normal_->upper || cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD could not copy AᵀA (status " + std::to_string(cm.status) +
                             ")");
  // Entries that are zero in exact arithmetic but left as round-off by the product are dropped:
  // every row of C sums to zero (Eq. 3), so the coupling of Δe with f(x_j) is exactly zero for
  // every j away from the two ends; a few ulps of it survive the sum and would make the Δe rows
  // denser than they are.  The threshold is 1e-13 of the largest entry, far below anything the
  // solution sees.
  cholmod_drop(1e-13 * max_abs, normal_->upper, &cm);

  impl_->L = cholmod_analyze(normal_->upper, &impl_->cm);
  if (!impl_->L || impl_->cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD symbolic analysis failed (status " +
                             std::to_string(impl_->cm.status) + ")");
  stats_.analyze_s = seconds_since(t0);
}

TikhonovSolver::~TikhonovSolver() = default;

std::unique_ptr<TikhonovSolver> TikhonovSolver::worker() const {
  std::unique_ptr<TikhonovSolver> w(new TikhonovSolver());
  w->A_ = A_;
  w->normal_ = normal_;
  w->sigma_max_bound_ = sigma_max_bound_;
  w->impl_ = std::make_unique<Impl>();
  w->impl_->L = cholmod_copy_factor(impl_->L, &w->impl_->cm);
  if (!w->impl_->L) throw std::runtime_error("CHOLMOD could not copy the factor for a worker");
  return w;
}

SolverStatus TikhonovSolver::factorize(double lambda) {
  const auto t0 = std::chrono::steady_clock::now();
  double beta[2] = {lambda * lambda, 0.0};  // AᵀA + βI with β = λ²
  const int ok = cholmod_factorize_p(normal_->upper, beta, nullptr, 0, impl_->L, &impl_->cm);
  ++stats_.factorizations;
  stats_.factorize_s += seconds_since(t0);
  lambda_ = lambda;
  // cholmod_factorize_p returns TRUE even when a pivot failed: check status and L->minor too.
  impl_->factor_ok = ok && impl_->cm.status == CHOLMOD_OK && impl_->L->minor == impl_->L->n;
  return impl_->factor_ok ? SolverStatus::success : SolverStatus::not_positive_definite;
}

Eigen::VectorXd TikhonovSolver::solve_normal(const Eigen::VectorXd& rhs) {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::solve_normal without a successful factorisation");
  if (rhs.size() != static_cast<Eigen::Index>(impl_->L->n))
    throw std::invalid_argument("TikhonovSolver::solve_normal: right-hand side has " +
                                std::to_string(rhs.size()) + " entries, expected " +
                                std::to_string(impl_->L->n));
  const auto t0 = std::chrono::steady_clock::now();
  cholmod_dense b = view(rhs);
  if (!cholmod_solve2(CHOLMOD_A, impl_->L, &b, nullptr, &impl_->X, nullptr, &impl_->Y, &impl_->E,
                      &impl_->cm))
    throw std::runtime_error("CHOLMOD solve failed (status " + std::to_string(impl_->cm.status) +
                             ")");
  Eigen::VectorXd out =
      Eigen::Map<const Eigen::VectorXd>(static_cast<const double*>(impl_->X->x), rhs.size());
  ++stats_.solves;
  stats_.solve_s += seconds_since(t0);
  return out;
}

double TikhonovSolver::inverse_quadratic_form(const Eigen::VectorXd& v) {
  const cholmod_factor* L = impl_->L;
  // With the natural ordering and a simplicial LDLᵀ factor, vᵀ(LDLᵀ)⁻¹v = Σ z_j²/D_j with
  // z = L⁻¹v: one triangular solve instead of two.  Any other factor kind: a full solve.
  if (!impl_->factor_ok || L->is_ll || L->is_super || L->ordering != CHOLMOD_NATURAL)
    return v.dot(solve_normal(v));
  if (v.size() != static_cast<Eigen::Index>(L->n))
    throw std::invalid_argument("TikhonovSolver::inverse_quadratic_form: wrong vector size");
  const auto t0 = std::chrono::steady_clock::now();
  cholmod_dense b = view(v);
  if (!cholmod_solve2(CHOLMOD_L, impl_->L, &b, nullptr, &impl_->X, nullptr, &impl_->Y, &impl_->E,
                      &impl_->cm))
    throw std::runtime_error("CHOLMOD solve failed (status " + std::to_string(impl_->cm.status) +
                             ")");
  const auto* z = static_cast<const double*>(impl_->X->x);
  const auto* Lp = static_cast<const int*>(L->p);
  const auto* Lx = static_cast<const double*>(L->x);
  double q = 0.0;
  for (size_t j = 0; j < L->n; ++j)
    q += z[j] * z[j] / Lx[Lp[j]];  // D_j on L's diagonal
  ++stats_.solves;
  stats_.solve_s += seconds_since(t0);
  return q;
}

Eigen::VectorXd TikhonovSolver::solve(const Eigen::VectorXd& b) {
  return solve_normal(A_->transpose() * b);
}

}  // namespace errsep::core
