#include "errsep/core/tikhonov_solver.hpp"

#include <cholmod.h>

#include <Eigen/Cholesky>
#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <optional>
#include <stdexcept>
#include <vector>

#include "band_ldlt.hpp"
#include "cholmod_views.hpp"

namespace errsep::core {
using detail::view;
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

std::string FactorFailure::message() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "lambda = %.4g rejected: factor not positive definite at pivot %lld of %lld%s "
                "(D = %.3g, diagonal %.3g)%s",
                lambda, static_cast<long long>(pivot), static_cast<long long>(unknowns),
                in_border ? " (the border's Schur complement)" : "", pivot_value, diagonal,
                stopped_by_cholmod ? ": CHOLMOD stopped at a zero pivot (singular)"
                                   : ": the round-off of the factorisation exceeds the matrix's "
                                     "smallest eigenvalue at this lambda (its digits are lost)");
  return buf;
}

// The upper triangle of AᵀA (stype = 1: CHOLMOD's up-looking simplicial factorisation reads it
// as it is; a lower-stored matrix would be transposed on every factorisation, 30% of its time).
// Read-only once built, so workers on other threads share it.
struct TikhonovSolver::Normal {
  cholmod_common cm{};
  cholmod_sparse* upper = nullptr;  ///< all of AᵀA (n × n, upper)
  /// The band block B: the leading m × m of `upper`.  Column j of an upper-stored matrix holds
  /// rows <= j only, so B is the first m columns of `upper` with the same arrays.
  cholmod_sparse band{};
  Eigen::MatrixXd C;  ///< m × k coupling of the band unknowns with the border (mostly zero)
  Eigen::MatrixXd D;  ///< k × k border block
  /// C = U·Vᵀ with V (k × r) orthonormal, r = rank C: the border needs r triangular solves per
  /// λ, not k.  For the four-sensor system r = 2 < k = 4: column j of C collects row j of
  /// Eq. (3)'s C along the ends of f, and that C has rank 2.
  Eigen::MatrixXd U, V;
  /// The penalty P of the general form: its band part aligned with upper->x (empty: CHOLMOD's
  /// shift λ²I), its coupling with the border C_P (m × k) and border block D_P (k × k), and
  /// U_P = C_P·V (V spans the rows of both C and C_P).
  std::vector<double> pen_x;
  /// Where pen_x is not zero (a second-difference penalty fills 3 of a column's 8 entries of the
  /// four-sensor band): a λ's values are AᵀA copied, plus λ² times these.
  std::vector<std::size_t> pen_nz;
  Eigen::MatrixXd C_P, D_P, U_P;
  /// The banded path (build_banded): B and P's band part in BandLdlt's upper band storage of
  /// half-bandwidth band_b (band_b < 0: the general path, factorised by CHOLMOD).  B's band is
  /// factorised by detail::BandLdlt, not CHOLMOD (band_ldlt.hpp: 5-10x faster for b = 7).
  int band_b = -1;
  std::vector<double> band_x, pen_band_x;
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
  Eigen::Index m = 0;  ///< unknowns of the band block
  /// The band block's factor: BandLdlt on the banded path, else CHOLMOD's (L).
  bool banded = false;
  detail::BandLdlt ldl;
  cholmod_factor* L = nullptr;
  /// Banded path: the multi-column forward substitution's output [L⁻¹U | L⁻¹rhs] (what Xk is
  /// for CHOLMOD), kept between λ.
  Eigen::MatrixXd Wk;
  // Solution and workspace of cholmod_solve2, kept between solves: a fresh 8 MB vector per solve
  // at N = 10⁶ costs page faults comparable to the solve itself.
  // One set per right-hand-side width (1 and the border's k): alternating widths in one set would
  // reallocate it on every call.
  cholmod_dense *X = nullptr, *Y = nullptr, *E = nullptr;
  cholmod_dense *Xk = nullptr, *Yk = nullptr, *Ek = nullptr;
  /// L⁻¹U (m × r): a view of the multi-column solve's output Xk, which only factorize()
  /// overwrites (no 8·m·r-byte copy per λ).
  Eigen::Map<const Eigen::MatrixXd> W{nullptr, 0, 0};
  /// [U | right-hand side] (m × (r + 1)) for factorize_and_solve: U copied in once.
  Eigen::MatrixXd rhs_block;
  /// Scratch m-vector (D_B⁻¹z), kept: a temporary per solve would cost page faults at N = 10⁶.
  Eigen::VectorXd zd;
  Eigen::VectorXd d;  ///< the diagonal D of the band's LDLᵀ
  // LDLᵀ with pivoting, not LLᵀ: like CHOLMOD's simplicial LDLᵀ of the whole matrix it fails only
  // on an exactly zero pivot.  At λ = 0 with the default gauge the bow direction (quadratic f with
  // Δe) is determined only by the weak gauge row, and for long scans (N ≳ 3000) its Schur pivot
  // is lost to round-off and may come out slightly negative; the least-squares solution is then
  // arbitrary in that one direction (Fig. 3(d)) but still usable for σ̂ from the residual.
  Eigen::LDLT<Eigen::MatrixXd> S;  ///< Schur complement D + λ²I − WᵀD⁻¹W of the border
  bool factor_ok = false;
  /// The selected inverse of the current factorisation once computed (a λ rule's edf and the
  /// posterior's u both ask for it at the chosen λ; at N = 10⁶ it costs 0.2 s).
  std::optional<SelectedInverse> selinv;
  /// With a penalty: the values of AᵀA + λ²P on the shared pattern (one array per solver, so
  /// workers factorise different λ at once), and the matrix header that points to them.
  std::vector<double> work_x;
  cholmod_sparse work{};
  Eigen::MatrixXd U_l;  ///< U + λ²U_P of the current λ (general form with a border)

  /// out = op⁻¹·v for CHOLMOD system `sys` (CHOLMOD_L or CHOLMOD_DLt) on the band factor, one
  /// column of `rows` entries.
  void band_solve(int sys, const double* v, Eigen::Index rows, double* out) {
    if (banded) {
      if (sys == CHOLMOD_L)
        ldl.forward(v, 1, out);
      else
        ldl.back_dlt(v, 1, out);
      return;
    }
    cholmod_dense b = view(v, rows, 1);
    if (!cholmod_solve2(sys, L, &b, nullptr, &X, nullptr, &Y, &E, &cm))
      throw std::runtime_error("CHOLMOD solve failed (status " + std::to_string(cm.status) + ")");
    std::copy_n(static_cast<const double*>(X->x), rows, out);
  }
  /// Xk = L⁻¹·v for the multi-column right-hand side v (rows × cols), left in Xk.
  void band_solve_k(const double* v, Eigen::Index rows, Eigen::Index cols) {
    if (banded) {
      Wk.resize(rows, cols);
      ldl.forward(v, cols, Wk.data());
      return;
    }
    cholmod_dense b = view(v, rows, cols);
    if (!cholmod_solve2(CHOLMOD_L, L, &b, nullptr, &Xk, nullptr, &Yk, &Ek, &cm))
      throw std::runtime_error("CHOLMOD solve failed (status " + std::to_string(cm.status) + ")");
  }
  /// The multi-column forward substitution's output (column-major, m rows).
  const double* forward_k() const { return banded ? Wk.data() : static_cast<const double*>(Xk->x); }
  Impl() { start_common(cm); }
  ~Impl() {
    cholmod_free_dense(&X, &cm);
    cholmod_free_dense(&Y, &cm);
    cholmod_free_dense(&E, &cm);
    cholmod_free_dense(&Xk, &cm);
    cholmod_free_dense(&Yk, &cm);
    cholmod_free_dense(&Ek, &cm);
    cholmod_free_factor(&L, &cm);
    cholmod_finish(&cm);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
};

TikhonovSolver::TikhonovSolver(const Eigen::SparseMatrix<double>& A, int border_columns,
                               const Eigen::SparseMatrix<double>& penalty)
    : A_(std::make_shared<const Eigen::SparseMatrix<double>>(A)) {
  build(border_columns, penalty);
}

TikhonovSolver::TikhonovSolver(Eigen::SparseMatrix<double>&& A, int border_columns,
                               const Eigen::SparseMatrix<double>& penalty)
    : A_(std::make_shared<const Eigen::SparseMatrix<double>>(std::move(A))) {
  build(border_columns, penalty);
}

void TikhonovSolver::build(int border_columns, const Eigen::SparseMatrix<double>& penalty) {
  normal_ = std::make_shared<Normal>();
  impl_ = std::make_unique<Impl>();
  border_ = border_columns;
  if (border_ < 0 || border_ >= A_->cols())
    throw std::invalid_argument("TikhonovSolver: border_columns = " + std::to_string(border_) +
                                " for a matrix with " + std::to_string(A_->cols()) + " columns");
  const auto t0 = std::chrono::steady_clock::now();
  // The rows of A as columns: AᵀA is the sum of their outer products.
  Eigen::SparseMatrix<double> At = A_->transpose();
  At.makeCompressed();
  const bool general_form = penalty.rows() > 0 || penalty.cols() > 0;
  if (general_form && (penalty.rows() != A_->cols() || penalty.cols() != A_->cols()))
    throw std::invalid_argument("TikhonovSolver: the penalty is " + std::to_string(penalty.rows()) +
                                "x" + std::to_string(penalty.cols()) + ", expected " +
                                std::to_string(A_->cols()) + " square (all unknowns)");
  stats_.banded_normal = build_banded(At, penalty);
  if (!stats_.banded_normal) {
    if (general_form)
      throw std::invalid_argument(
          "TikhonovSolver: a penalty needs narrow rows (the banded normal matrix)");
    build_general(At);
  }
  impl_->m = A_->cols() - border_;
  impl_->banded = normal_->band_b >= 0;
  if (general_form && !impl_->banded) {
    impl_->work_x.assign(static_cast<const double*>(normal_->band.x),
                         static_cast<const double*>(normal_->band.x) + normal_->pen_x.size());
    impl_->work = normal_->band;
    impl_->work.x = impl_->work_x.data();
  }
  compress_border();
  stats_.analyze_s = seconds_since(t0);
  if (impl_->banded) return;  // BandLdlt needs no analysis: the band is its structure
  const auto t1 = std::chrono::steady_clock::now();
  impl_->L = cholmod_analyze(&normal_->band, &impl_->cm);
  if (!impl_->L || impl_->cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD symbolic analysis failed (status " +
                             std::to_string(impl_->cm.status) + ")");
  // The border elimination and inverse_quadratic_form read D off the simplicial LDLᵀ factor and
  // assume no fill-reducing permutation (the natural order of a band is already fill-free).
  if (impl_->L->ordering != CHOLMOD_NATURAL || impl_->L->is_super)
    throw std::runtime_error("CHOLMOD did not keep the natural-order simplicial factor");
  stats_.analyze_s += seconds_since(t1);
}

// AᵀA straight from A's rows when the band unknowns of every row lie within a narrow band: the
// four-sensor system's rows span s2+s3+s4+1 samples of f (Eq. 8), its constraint rows one or two.
// Each row's outer product is added into band storage (the border into C and D), which is then
// written as CHOLMOD's upper-stored band: O(nnz(A)·row length), and 4-5x faster at N = 10⁶ than
// the general sparse product (cholmod_aat) it replaces.  False (nothing built) for a wide row.
bool TikhonovSolver::build_banded(const Eigen::SparseMatrix<double>& At,
                                  const Eigen::SparseMatrix<double>& P) {
  constexpr int kMaxBand = 64;
  const Eigen::Index n = At.rows(), m = n - border_, rows = At.cols();
  const int* p = At.outerIndexPtr();
  const int* idx = At.innerIndexPtr();
  const double* val = At.valuePtr();
  const bool general_form = P.rows() > 0;
  int bw = 0;
  for (int j = 0; j < P.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(P, j); it; ++it)
      if (it.row() < m && it.col() < m)
        bw = std::max(bw, static_cast<int>(std::abs(it.row() - it.col())));
  if (bw > kMaxBand) return false;
  for (Eigen::Index r = 0; r < rows; ++r) {
    int lo = -1, hi = -1;
    for (int q = p[r]; q < p[r + 1]; ++q)
      if (idx[q] < m) {
        if (lo < 0) lo = idx[q];
        hi = idx[q];  // sorted: the last band index is the largest
      }
    if (lo >= 0) bw = std::max(bw, hi - lo);
    if (bw > kMaxBand) return false;
  }
  const auto w = static_cast<std::size_t>(bw + 1);
  std::vector<double> band(w * static_cast<std::size_t>(m), 0.0);  // (i, j), i <= j: [j·w + j−i]
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(m, border_),
                  D = Eigen::MatrixXd::Zero(border_, border_);
  for (Eigen::Index r = 0; r < rows; ++r)
    for (int a = p[r]; a < p[r + 1]; ++a)
      for (int b = a; b < p[r + 1]; ++b) {  // idx[b] >= idx[a]
        const int i = idx[a], j = idx[b];
        const double v = val[a] * val[b];
        if (j < m) {
          band[static_cast<std::size_t>(j) * w + static_cast<std::size_t>(j - i)] += v;
        } else if (i < m) {
          C(i, j - m) += v;
        } else {
          D(i - m, j - m) += v;
          if (i != j) D(j - m, i - m) += v;
        }
      }
  // Round-off of exact zeros is dropped (see build_general): 1e-13 of the largest entry.
  double max_abs = 0.0;
  for (double v : band)
    max_abs = std::max(max_abs, std::abs(v));
  if (border_ > 0) max_abs = std::max({max_abs, C.cwiseAbs().maxCoeff(), D.cwiseAbs().maxCoeff()});
  const double tol = 1e-13 * max_abs;
  for (double& v : band)
    if (std::abs(v) <= tol) v = 0.0;
  C = C.unaryExpr([tol](double v) { return std::abs(v) <= tol ? 0.0 : v; });
  // The penalty in the same band storage (upper triangle: i <= j).
  std::vector<double> pband;
  if (general_form) {
    pband.assign(band.size(), 0.0);
    normal_->C_P = Eigen::MatrixXd::Zero(m, border_);
    normal_->D_P = Eigen::MatrixXd::Zero(border_, border_);
    for (int j = 0; j < P.outerSize(); ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(P, j); it; ++it) {
        const Eigen::Index r = it.row(), c = it.col();
        if (r < m && c < m) {
          if (r <= c)
            pband[static_cast<std::size_t>(c) * w + static_cast<std::size_t>(c - r)] += it.value();
        } else if (r < m) {
          normal_->C_P(r, c - m) = it.value();
        } else if (c >= m) {
          normal_->D_P(r - m, c - m) = it.value();
        }
      }
  }
  // An entry is in the pattern when AᵀA or P has it (the diagonal always).
  auto kept = [&](std::size_t q, int d) {
    return d == 0 || band[q] != 0.0 || (general_form && pband[q] != 0.0);
  };
  // ‖AᵀA‖₁ (column sums of the symmetric matrix) bounds λ_max(AᵀA) = σ_max(A)².
  Eigen::VectorXd colsum = Eigen::VectorXd::Zero(n);
  std::size_t nnz = 0;
  for (Eigen::Index j = 0; j < m; ++j)
    for (int d = 0; d <= bw && d <= j; ++d) {
      const std::size_t q = static_cast<std::size_t>(j) * w + static_cast<std::size_t>(d);
      const double v = band[q];
      if (!kept(q, d)) continue;
      ++nnz;
      colsum(j) += std::abs(v);
      if (d > 0) colsum(j - d) += std::abs(v);
    }
  for (Eigen::Index c = 0; c < border_; ++c) {
    colsum.head(m) += C.col(c).cwiseAbs();
    colsum(m + c) += C.col(c).cwiseAbs().sum() + D.col(c).cwiseAbs().sum();
  }
  sigma_max_bound_ = std::sqrt(colsum.maxCoeff());

  cholmod_common& cm = normal_->cm;
  normal_->upper = cholmod_allocate_sparse(static_cast<size_t>(m), static_cast<size_t>(m), nnz, 1,
                                           1, 1, CHOLMOD_REAL, &cm);
  if (!normal_->upper || cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD could not allocate AᵀA (status " + std::to_string(cm.status) +
                             ")");
  auto* up = static_cast<int*>(normal_->upper->p);
  auto* ui = static_cast<int*>(normal_->upper->i);
  auto* ux = static_cast<double*>(normal_->upper->x);
  int k = 0;
  if (general_form) normal_->pen_x.assign(nnz, 0.0);
  for (Eigen::Index j = 0; j < m; ++j) {
    up[j] = k;
    for (int d = std::min<int>(bw, static_cast<int>(j)); d >= 0; --d) {  // rows ascending
      const std::size_t q = static_cast<std::size_t>(j) * w + static_cast<std::size_t>(d);
      if (!kept(q, d)) continue;
      ui[k] = static_cast<int>(j) - d;
      ux[k] = band[q];
      if (general_form) normal_->pen_x[static_cast<std::size_t>(k)] = pband[q];
      ++k;
    }
  }
  up[m] = k;
  for (std::size_t q = 0; q < normal_->pen_x.size(); ++q)
    if (normal_->pen_x[q] != 0.0) normal_->pen_nz.push_back(q);
  normal_->band = *normal_->upper;
  normal_->C = std::move(C);
  normal_->D = std::move(D);
  normal_->band_b = bw;
  normal_->band_x = std::move(band);
  if (general_form) normal_->pen_band_x = std::move(pband);
  return true;
}

// C = U·Vᵀ with V the right singular vectors of C whose singular values exceed 1e-12 of the
// largest: the directions of the border that the band sees.  The SVD is of C's nonzero rows
// (a few near the ends of f for the four-sensor system), which have the same V; a Gram-matrix
// eigendecomposition would blur a zero singular value into ~1e-8 of the largest.
void TikhonovSolver::compress_border() {
  const Eigen::MatrixXd& C = normal_->C;
  const Eigen::Index k = C.cols();
  const bool with_pen = normal_->C_P.size() > 0;
  // The rows of C (and of the penalty's coupling C_P: V must span both) that are not zero.
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < C.rows() && k > 0; ++i) {
    if (C.row(i).cwiseAbs().maxCoeff() > 0.0) rows.push_back(-(i + 1));
    if (with_pen && normal_->C_P.row(i).cwiseAbs().maxCoeff() > 0.0) rows.push_back(i + 1);
  }
  Eigen::MatrixXd Cs(static_cast<Eigen::Index>(rows.size()), k);
  const Eigen::MatrixXd& CP = normal_->C_P;
  for (std::size_t q = 0; q < rows.size(); ++q) {
    if (rows[q] < 0)
      Cs.row(static_cast<Eigen::Index>(q)) = C.row(-rows[q] - 1);
    else
      Cs.row(static_cast<Eigen::Index>(q)) = CP.row(rows[q] - 1);
  }
  Eigen::Index r = 0;
  if (Cs.rows() > 0) {
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Cs, Eigen::ComputeFullV);
    const Eigen::VectorXd& sv = svd.singularValues();  // descending
    while (r < sv.size() && sv(r) > 1e-12 * sv(0))
      ++r;
    normal_->V = svd.matrixV().leftCols(r);
  } else {
    normal_->V.resize(k, 0);
  }
  normal_->U = C * normal_->V;
  if (with_pen) normal_->U_P = normal_->C_P * normal_->V;
  stats_.border_rank = static_cast<int>(r);
}

// The general case: AᵀA = F·Fᵀ with F = Aᵀ (cholmod_aat; 3x faster than Eigen's sparse-sparse
// product here), its upper triangle kept, the border split off as C and D.
void TikhonovSolver::build_general(const Eigen::SparseMatrix<double>& At) {
  cholmod_common& cm = normal_->cm;
  cholmod_sparse F = view(At);
  cholmod_sparse* full = cholmod_aat(&F, nullptr, 0, 1, &cm);
  if (!full || cm.status < CHOLMOD_OK)
    throw std::runtime_error("CHOLMOD could not form AᵀA (status " + std::to_string(cm.status) +
                             ")");
  double norm1 = 0.0, max_abs = 0.0;  // ‖AᵀA‖₁ >= λ_max(AᵀA) = σ_max(A)²
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

  const auto n = static_cast<Eigen::Index>(normal_->upper->ncol);
  const Eigen::Index m = n - border_;
  normal_->band = *normal_->upper;
  normal_->band.nrow = normal_->band.ncol = static_cast<size_t>(m);
  normal_->C = Eigen::MatrixXd::Zero(m, border_);
  normal_->D = Eigen::MatrixXd::Zero(border_, border_);
  const auto* p = static_cast<const int*>(normal_->upper->p);
  const auto* i = static_cast<const int*>(normal_->upper->i);
  const auto* x = static_cast<const double*>(normal_->upper->x);
  for (Eigen::Index c = m; c < n; ++c)
    for (int q = p[c]; q < p[c + 1]; ++q) {
      if (i[q] < m) {
        normal_->C(i[q], c - m) = x[q];
      } else {
        normal_->D(i[q] - m, c - m) = x[q];
        normal_->D(c - m, i[q] - m) = x[q];
      }
    }
}

TikhonovSolver::~TikhonovSolver() = default;

std::unique_ptr<TikhonovSolver> TikhonovSolver::worker() const {
  std::unique_ptr<TikhonovSolver> w(new TikhonovSolver());
  w->A_ = A_;
  w->normal_ = normal_;
  w->sigma_max_bound_ = sigma_max_bound_;
  w->border_ = border_;
  w->impl_ = std::make_unique<Impl>();
  w->impl_->m = impl_->m;
  w->impl_->banded = impl_->banded;
  if (impl_->banded) return w;
  w->impl_->L = cholmod_copy_factor(impl_->L, &w->impl_->cm);
  if (!w->impl_->L) throw std::runtime_error("CHOLMOD could not copy the factor for a worker");
  if (has_penalty()) {
    w->impl_->work_x = impl_->work_x;
    w->impl_->work = normal_->band;
    w->impl_->work.x = w->impl_->work_x.data();
  }
  return w;
}

SolverStatus TikhonovSolver::factorize(double lambda) {
  return factorize_impl(lambda, nullptr, nullptr, nullptr);
}

SolverStatus TikhonovSolver::factorize_and_solve(double lambda, const Eigen::VectorXd& rhs,
                                                 Eigen::VectorXd& x) {
  const Eigen::Index m = impl_->m;
  if (rhs.size() != m + border_)
    throw std::invalid_argument("TikhonovSolver::factorize_and_solve: right-hand side has " +
                                std::to_string(rhs.size()) + " entries, expected " +
                                std::to_string(m + border_));
  return factorize_impl(lambda, &rhs, &x, nullptr);
}

SolverStatus TikhonovSolver::factorize_and_quadratic_form(double lambda, const Eigen::VectorXd& v,
                                                          double& q) {
  const Eigen::Index m = impl_->m;
  if (v.size() != m + border_)
    throw std::invalid_argument("TikhonovSolver::factorize_and_quadratic_form: vector has " +
                                std::to_string(v.size()) + " entries, expected " +
                                std::to_string(m + border_));
  return factorize_impl(lambda, &v, nullptr, &q);
}

SolverStatus TikhonovSolver::factorize_impl(double lambda, const Eigen::VectorXd* rhs,
                                            Eigen::VectorXd* x, double* quad) {
  const auto t0 = std::chrono::steady_clock::now();
  const bool general_form = has_penalty();
  const double l2 = lambda * lambda;
  const Eigen::Index m = impl_->m;
  impl_->selinv.reset();
  ++stats_.factorizations;
  lambda_ = lambda;
  failure_ = FactorFailure{};
  failure_.lambda = lambda;
  failure_.unknowns = m + border_;
  // The border's block LDLᵀ of [B C; Cᵀ D] with C = U·Vᵀ needs W = L⁻¹U; with a right-hand
  // side, its forward substitution rides along in the same multi-column pass over the factor
  // (CHOLMOD takes up to 4 columns in one pass over L; BandLdlt does it while it factorises).
  const Eigen::Index r = border_ > 0 ? normal_->U.cols() : 0;
  const bool fuse = rhs != nullptr && r > 0 && r + 1 <= 4;
  // The coupling of this λ: U, or U + λ²U_P when the penalty reaches the border.
  const bool pen_border = border_ > 0 && general_form && normal_->U_P.size() > 0;
  if (pen_border) impl_->U_l = normal_->U + l2 * normal_->U_P;
  const Eigen::MatrixXd& U = pen_border ? impl_->U_l : normal_->U;
  if (fuse) {
    if (impl_->rhs_block.rows() != m || impl_->rhs_block.cols() != r + 1 || pen_border) {
      impl_->rhs_block.resize(m, r + 1);
      impl_->rhs_block.leftCols(r) = U;
    }
    impl_->rhs_block.col(r) = rhs->head(m);
  }
  const double* forward_in = fuse ? impl_->rhs_block.data() : (r > 0 ? U.data() : nullptr);
  const Eigen::Index forward_cols = fuse ? r + 1 : r;

  if (impl_->banded) {
    // B + λ²P, or B + λ²I without a penalty, read from the shared band as it is factorised.
    const auto w = static_cast<std::size_t>(normal_->band_b + 1);
    const double* pen = general_form ? normal_->pen_band_x.data() : nullptr;
    const double shift = general_form ? 0.0 : l2;
    impl_->Wk.resize(m, forward_cols);
    const Eigen::Index bad =
        impl_->ldl.factorize(normal_->band_x.data(), pen, l2, shift, m, normal_->band_b, forward_in,
                             forward_cols, impl_->Wk.data());
    impl_->factor_ok = bad < 0;
    if (bad >= 0) {
      const auto q = static_cast<std::size_t>(bad) * w;
      failure_.pivot = bad;
      failure_.pivot_value = impl_->ldl.d()(bad);
      failure_.diagonal = normal_->band_x[q] + shift + (pen != nullptr ? l2 * pen[q] : 0.0);
    } else {
      impl_->d = impl_->ldl.d();
    }
  } else {
    // B + βI with β = λ² (CHOLMOD's shift), or B + λ²P written into this solver's value array.
    double beta[2] = {general_form ? 0.0 : l2, 0.0};
    if (general_form) {
      const auto* a = static_cast<const double*>(normal_->band.x);
      const double* pen = normal_->pen_x.data();
      double* wx = impl_->work_x.data();
      std::copy_n(a, impl_->work_x.size(), wx);
      for (const std::size_t q : normal_->pen_nz)
        wx[q] += l2 * pen[q];
    }
    const int ok = cholmod_factorize_p(general_form ? &impl_->work : &normal_->band, beta, nullptr,
                                       0, impl_->L, &impl_->cm);
    // cholmod_factorize_p returns TRUE even when a pivot failed: check status and L->minor too.
    impl_->factor_ok =
        ok && impl_->cm.status == CHOLMOD_OK && impl_->L->minor == impl_->L->n && !impl_->L->is_ll;
    // The matrix's diagonal entry j of the band (upper storage: the last entry of column j).
    auto band_diagonal = [&](Eigen::Index j) {
      const cholmod_sparse& B = general_form ? impl_->work : normal_->band;
      const int q = static_cast<const int*>(B.p)[j + 1] - 1;
      return static_cast<const double*>(B.x)[q] + beta[0];
    };
    if (!impl_->factor_ok && impl_->L->minor < impl_->L->n) {
      const auto j = static_cast<Eigen::Index>(impl_->L->minor);
      failure_.pivot = j;
      failure_.diagonal = band_diagonal(j);
      failure_.stopped_by_cholmod = true;
    }
    if (impl_->factor_ok) {
      const auto* Lp = static_cast<const int*>(impl_->L->p);
      const auto* Lx = static_cast<const double*>(impl_->L->x);
      impl_->d.resize(m);
      for (Eigen::Index j = 0; j < m; ++j)
        impl_->d(j) = Lx[Lp[j]];  // D_j on L's diagonal
      // CHOLMOD's LDLᵀ stops only at an exactly zero pivot and takes a negative one silently:
      // the matrix is then indefinite to working precision (log det NaN, a meaningless
      // solution).
      for (Eigen::Index j = 0; j < m; ++j)
        if (!(impl_->d(j) > 0.0 && std::isfinite(impl_->d(j)))) {
          impl_->factor_ok = false;
          failure_.pivot = j;
          failure_.pivot_value = impl_->d(j);
          failure_.diagonal = band_diagonal(j);
          break;
        }
    }
    if (impl_->factor_ok && forward_cols > 0) impl_->band_solve_k(forward_in, m, forward_cols);
  }
  bool solved = false;
  if (impl_->factor_ok) {
    if (border_ > 0) {
      // Schur complement S = D + λ²I − V·(WᵀD_B⁻¹W)·Vᵀ of the border.
      new (&impl_->W) Eigen::Map<const Eigen::MatrixXd>(r > 0 ? impl_->forward_k() : nullptr, m, r);
      // WᵀD_B⁻¹W in one pass over the rows of W (no m × r temporary: memory traffic is what a
      // λ costs at N = 10⁶).
      const double* Wp = impl_->W.data();
      const double* dp = impl_->d.data();
      Eigen::MatrixXd acc = Eigen::MatrixXd::Zero(r, r);
      Eigen::VectorXd row(r);
      for (Eigen::Index j = 0; j < m && r > 0; ++j) {
        const double inv = 1.0 / dp[j];
        for (Eigen::Index a = 0; a < r; ++a)
          row(a) = Wp[a * m + j];
        for (Eigen::Index b = 0; b < r; ++b)
          for (Eigen::Index a = 0; a <= b; ++a)
            acc(a, b) += row(a) * row(b) * inv;
      }
      acc.triangularView<Eigen::StrictlyLower>() = acc.transpose();
      Eigen::MatrixXd S = normal_->D;
      if (!general_form)
        S.diagonal().array() += lambda * lambda;
      else if (normal_->D_P.size() > 0)
        S += (lambda * lambda) * normal_->D_P;
      S.noalias() -= normal_->V * acc * normal_->V.transpose();
      impl_->S.compute(S);
      impl_->factor_ok = impl_->S.info() == Eigen::Success;
      // With a penalty the whole matrix is positive definite in exact arithmetic (the posterior
      // precision), so a border pivot <= 0 is lost precision like a band one.  Without one, a
      // slightly negative Schur pivot at λ = 0 is the weak gauge row's bow direction (see Impl::S)
      // and is tolerated.
      if (impl_->factor_ok && general_form) {
        const Eigen::VectorXd sd = impl_->S.vectorD();
        for (Eigen::Index c = 0; c < sd.size(); ++c)
          if (!(sd(c) > 0.0 && std::isfinite(sd(c)))) {
            impl_->factor_ok = false;
            failure_.pivot = m + c;
            failure_.pivot_value = sd(c);
            failure_.diagonal = S(c, c);
            failure_.in_border = true;
            break;
          }
      } else if (!impl_->factor_ok) {
        failure_.pivot = m;
        failure_.in_border = true;
      }
      if (fuse && impl_->factor_ok) {
        const auto t1 = std::chrono::steady_clock::now();
        const Eigen::Map<const Eigen::VectorXd> zf(impl_->forward_k() + r * m, m);
        if (quad != nullptr) {
          // vᵀM⁻¹v from the forward substitution alone (as inverse_quadratic_form): no back
          // substitution, which is a third of a λ's passes over the factor.
          *quad = quadratic_form_from_forward(*rhs, zf);
        } else {
          Eigen::VectorXd z = zf;
          finish_solve(*rhs, z, *x);
        }
        ++stats_.solves;
        stats_.solve_s += seconds_since(t1);
        solved = true;
      }
    }
  }
  stats_.factorize_s += seconds_since(t0);
  if (!impl_->factor_ok) return SolverStatus::not_positive_definite;
  if (rhs != nullptr && !solved) {
    if (quad != nullptr)
      *quad = inverse_quadratic_form(*rhs);
    else
      *x = solve_normal(*rhs);
  }
  return SolverStatus::success;
}

// zᵀD_B⁻¹z + tᵀS⁻¹t with t = v₂ − V·WᵀD_B⁻¹z, z = L⁻¹v₁: vᵀM⁻¹v of the block LDLᵀ.
double TikhonovSolver::quadratic_form_from_forward(const Eigen::VectorXd& v,
                                                   const Eigen::Ref<const Eigen::VectorXd>& z) {
  impl_->zd = z.cwiseQuotient(impl_->d);
  double q = z.dot(impl_->zd);
  if (border_ > 0) {
    const Eigen::VectorXd t = v.tail(border_) - normal_->V * (impl_->W.transpose() * impl_->zd);
    q += t.dot(impl_->S.solve(t));
  }
  return q;
}

// From z = L⁻¹r₁: y = S⁻¹(r₂ − V·WᵀD_B⁻¹z), x = (D_B Lᵀ)⁻¹(z − W·Vᵀy).
void TikhonovSolver::finish_solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& z,
                                  Eigen::VectorXd& out) {
  const Eigen::Index m = impl_->m;
  impl_->zd.resize(m);
  impl_->zd = z.cwiseQuotient(impl_->d);
  const Eigen::VectorXd y =
      impl_->S.solve(rhs.tail(border_) - normal_->V * (impl_->W.transpose() * impl_->zd));
  z.noalias() -= impl_->W * (normal_->V.transpose() * y);
  out.resize(m + border_);
  impl_->band_solve(CHOLMOD_DLt, z.data(), m, out.data());
  out.tail(border_) = y;
}

Eigen::VectorXd TikhonovSolver::solve_normal(const Eigen::VectorXd& rhs) {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::solve_normal without a successful factorisation");
  const Eigen::Index m = impl_->m;
  if (rhs.size() != m + border_)
    throw std::invalid_argument("TikhonovSolver::solve_normal: right-hand side has " +
                                std::to_string(rhs.size()) + " entries, expected " +
                                std::to_string(m + border_));
  const auto t0 = std::chrono::steady_clock::now();
  Eigen::VectorXd out(rhs.size());
  if (border_ == 0 && impl_->banded) {
    impl_->ldl.forward(rhs.data(), 1, out.data());
    impl_->ldl.back_dlt(out.data(), 1, out.data());
  } else if (border_ == 0) {
    cholmod_dense b = view(rhs.data(), rhs.size(), 1);
    if (!cholmod_solve2(CHOLMOD_A, impl_->L, &b, nullptr, &impl_->X, nullptr, &impl_->Y, &impl_->E,
                        &impl_->cm))
      throw std::runtime_error("CHOLMOD solve failed (status " + std::to_string(impl_->cm.status) +
                               ")");
    out = Eigen::Map<const Eigen::VectorXd>(static_cast<const double*>(impl_->X->x), m);
  } else {
    Eigen::VectorXd z(m);
    impl_->band_solve(CHOLMOD_L, rhs.data(), m, z.data());
    finish_solve(rhs, z, out);
  }
  ++stats_.solves;
  stats_.solve_s += seconds_since(t0);
  return out;
}

double TikhonovSolver::inverse_quadratic_form(const Eigen::VectorXd& v) {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::inverse_quadratic_form without a factorisation");
  const Eigen::Index m = impl_->m;
  if (v.size() != m + border_)
    throw std::invalid_argument("TikhonovSolver::inverse_quadratic_form: wrong vector size");
  const auto t0 = std::chrono::steady_clock::now();
  // vᵀM⁻¹v = zᵀD_B⁻¹z + tᵀS⁻¹t with z = L⁻¹v₁, t = v₂ − V·WᵀD_B⁻¹z: one triangular solve.
  Eigen::VectorXd z(m);
  impl_->band_solve(CHOLMOD_L, v.data(), m, z.data());
  const double q = quadratic_form_from_forward(v, z);
  ++stats_.solves;
  stats_.solve_s += seconds_since(t0);
  return q;
}

Eigen::VectorXd TikhonovSolver::solve(const Eigen::VectorXd& b) {
  return solve_normal(A_->transpose() * b);
}

bool TikhonovSolver::factorized() const {
  return impl_->factor_ok;
}

bool TikhonovSolver::has_penalty() const {
  return !normal_->pen_x.empty();
}

Eigen::VectorXd TikhonovSolver::apply_penalty(const Eigen::VectorXd& x) const {
  const auto n = static_cast<Eigen::Index>(A_->cols());
  if (x.size() != n)
    throw std::invalid_argument("TikhonovSolver::apply_penalty: vector has " +
                                std::to_string(x.size()) + " entries, expected " +
                                std::to_string(n));
  if (!has_penalty()) return x;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(n);
  const auto* p = static_cast<const int*>(normal_->band.p);
  const auto* i = static_cast<const int*>(normal_->band.i);
  const double* v = normal_->pen_x.data();
  const auto m = static_cast<Eigen::Index>(normal_->band.ncol);
  for (Eigen::Index j = 0; j < m; ++j)
    for (int q = p[j]; q < p[j + 1]; ++q) {
      if (v[q] == 0.0) continue;
      out(i[q]) += v[q] * x(j);
      if (i[q] != j) out(j) += v[q] * x(i[q]);
    }
  if (border_ > 0 && normal_->C_P.size() > 0) {
    out.head(m).noalias() += normal_->C_P * x.tail(border_);
    out.tail(border_).noalias() += normal_->C_P.transpose() * x.head(m);
    out.tail(border_).noalias() += normal_->D_P * x.tail(border_);
  }
  return out;
}

double TikhonovSolver::log_det() const {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::log_det without a successful factorisation");
  double s = impl_->d.array().log().sum();
  if (border_ > 0) s += impl_->S.vectorD().array().abs().log().sum();
  return s;
}

double SelectedInverse::operator()(Eigen::Index i, Eigen::Index j) const {
  const Eigen::Index m = band_size;
  if (i >= m && j >= m) return border(i - m, j - m);
  if (i >= m) return cross(j, i - m);
  if (j >= m) return cross(i, j - m);
  const Eigen::Index a = std::min(i, j), b = std::max(i, j);
  const double z =
      b - a <= bandwidth
          ? band[static_cast<std::size_t>(a) * static_cast<std::size_t>(bandwidth + 1) +
                 static_cast<std::size_t>(b - a)]
          : std::numeric_limits<double>::quiet_NaN();
  if (std::isnan(z))
    throw std::out_of_range("SelectedInverse: entry (" + std::to_string(i) + ", " +
                            std::to_string(j) + ") is outside the factor's pattern");
  return z;
}

// Takahashi's recurrence on the band's LDLᵀ (L unit lower): Z = D⁻¹L⁻¹ + (I − Lᵀ)Z gives, column
// by column from the last, Z(i, j) = −Σ_k L(k, j)·Z(k, i) for j < i <= j + b (k over the pattern
// of column j) and Z(j, j) = 1/D_j − Σ_k L(k, j)·Z(k, j): every Z(k, i) needed lies inside the
// band, so the band of the inverse costs O(m·b²) and nothing outside it is formed.  The whole
// band, not only the pattern of L: a pair of unknowns that a quantity couples can lie outside the
// pattern where AᵀA has an exact zero near the start of the band (the four-sensor spacings
// (2, 3, 10): QQᵀ has a zero entry, and u_S at the first positions needs it).  The border
// adds the low-rank term of the block inverse: with Y = B⁻¹C and the Schur block S,
// M⁻¹ = [B⁻¹ + Y S⁻¹Yᵀ, −Y S⁻¹; −S⁻¹Yᵀ, S⁻¹].
const SelectedInverse& TikhonovSolver::selected_inverse() {
  if (!impl_->factor_ok)
    throw std::logic_error("TikhonovSolver::selected_inverse without a successful factorisation");
  if (impl_->selinv) return *impl_->selinv;
  const auto t0 = std::chrono::steady_clock::now();
  const Eigen::Index m = impl_->m;
  const bool banded = impl_->banded;
  const cholmod_factor* L = impl_->L;
  const auto* Lp = banded ? nullptr : static_cast<const int*>(L->p);
  const auto* Li = banded ? nullptr : static_cast<const int*>(L->i);
  const auto* Lx = banded ? nullptr : static_cast<const double*>(L->x);
  const auto* Lnz = banded ? nullptr : static_cast<const int*>(L->nz);
  int bw = banded ? normal_->band_b : 0;
  for (Eigen::Index j = 0; j < m && !banded; ++j)
    for (int q = Lp[j] + 1; q < Lp[j] + Lnz[j]; ++q)
      bw = std::max(bw, Li[q] - static_cast<int>(j));
  SelectedInverse z;
  z.bandwidth = bw;
  z.band_size = m;
  const auto w = static_cast<std::size_t>(bw + 1);
  z.band.assign(static_cast<std::size_t>(m) * w, std::numeric_limits<double>::quiet_NaN());
  auto at = [&](Eigen::Index a, Eigen::Index b) -> double& {
    if (a > b) std::swap(a, b);
    return z.band[static_cast<std::size_t>(a) * w + static_cast<std::size_t>(b - a)];
  };
  if (banded) {
    // The same recurrence on BandLdlt's rows, summed in the same order, with the band's index
    // arithmetic written out (at N = 10⁶ the general loop's per-entry bookkeeping was most of
    // the selected inverse's time).
    double* zb = z.band.data();
    std::array<double, 64> lv{};  // column j of L below the diagonal (bw <= 64: build_banded)
    for (Eigen::Index j = m - 1; j >= 0; --j) {
      const Eigen::Index cnt = std::min<Eigen::Index>(m - 1, j + bw) - j;
      for (Eigen::Index t = 0; t < cnt; ++t)
        lv[static_cast<std::size_t>(t)] = impl_->ldl.l(j + 1 + t, j);
      const auto jw = static_cast<std::size_t>(j) * w;
      for (Eigen::Index i = j + 1; i <= j + cnt; ++i) {
        double s = 0.0;
        for (Eigen::Index t = 0; t < cnt; ++t) {
          const Eigen::Index a = j + 1 + t;  // Z(a, i) of the band: (min, |a − i|)
          const std::size_t q =
              a <= i ? static_cast<std::size_t>(a) * w + static_cast<std::size_t>(i - a)
                     : static_cast<std::size_t>(i) * w + static_cast<std::size_t>(a - i);
          s += lv[static_cast<std::size_t>(t)] * zb[q];
        }
        zb[jw + static_cast<std::size_t>(i - j)] = -s;
      }
      double s = 0.0;
      for (Eigen::Index t = 0; t < cnt; ++t)
        s += lv[static_cast<std::size_t>(t)] * zb[jw + 1 + static_cast<std::size_t>(t)];
      zb[jw] = 1.0 / impl_->d(j) - s;
    }
  }
  std::vector<int> rows;
  std::vector<double> vals;
  for (Eigen::Index j = m - 1; j >= 0 && !banded; --j) {
    rows.clear();
    vals.clear();
    for (int q = Lp[j] + 1; q < Lp[j] + Lnz[j]; ++q) {
      rows.push_back(Li[q]);
      vals.push_back(Lx[q]);
    }
    const Eigen::Index last = std::min<Eigen::Index>(m - 1, j + bw);
    for (Eigen::Index i = j + 1; i <= last; ++i) {
      double s = 0.0;
      for (std::size_t b = 0; b < rows.size(); ++b)
        s += vals[b] * at(rows[b], i);
      at(j, i) = -s;
    }
    double s = 0.0;
    for (std::size_t b = 0; b < rows.size(); ++b)
      s += vals[b] * at(rows[b], j);
    at(j, j) = 1.0 / impl_->d(j) - s;
  }
  if (border_ > 0) {
    // Y = B⁻¹C = (B⁻¹U)·Vᵀ, B⁻¹U = L⁻ᵀD⁻¹·(L⁻¹U) from the W kept by the factorisation.
    // All r columns in one pass over the factor (into their own CHOLMOD buffers: Xk holds W).
    const Eigen::Index r = normal_->U.cols();
    Eigen::MatrixXd BinvU(m, r);
    if (r > 0 && banded) {
      impl_->ldl.back_dlt(impl_->W.data(), r, BinvU.data());
    } else if (r > 0) {
      cholmod_dense wv = view(impl_->W.data(), m, r);
      cholmod_dense *X = nullptr, *Y = nullptr, *E = nullptr;
      const int ok =
          cholmod_solve2(CHOLMOD_DLt, impl_->L, &wv, nullptr, &X, nullptr, &Y, &E, &impl_->cm);
      if (ok) BinvU = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(X->x), m, r);
      cholmod_free_dense(&X, &impl_->cm);
      cholmod_free_dense(&Y, &impl_->cm);
      cholmod_free_dense(&E, &impl_->cm);
      if (!ok)
        throw std::runtime_error("CHOLMOD solve failed (status " +
                                 std::to_string(impl_->cm.status) + ")");
    }
    z.border = impl_->S.solve(Eigen::MatrixXd::Identity(border_, border_));
    z.cross = -(BinvU * (normal_->V.transpose() * z.border));  // −Y·S⁻¹, Y = B⁻¹U·Vᵀ
    // The band of Y·S⁻¹·Yᵀ = B⁻¹U·H·(B⁻¹U)ᵀ, H = VᵀS⁻¹V (r × r): rows of B⁻¹U and of B⁻¹U·H
    // row-major, r multiply-adds per entry (a dynamic-size row product per entry cost more than
    // the whole recurrence at N = 10⁶).
    using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const RowMajor Bu = BinvU;
    const RowMajor Ch = Bu * (normal_->V.transpose() * z.border * normal_->V);
    const double* bu = Bu.data();
    const double* ch = Ch.data();
    for (Eigen::Index i = 0; i < m; ++i) {
      const double* ci = ch + i * r;
      double* zi = z.band.data() + static_cast<std::size_t>(i) * w;
      const Eigen::Index last = std::min<Eigen::Index>(m - 1, i + bw);
      for (Eigen::Index j = i; j <= last; ++j) {
        const double* bj = bu + j * r;
        double acc = 0.0;
        for (Eigen::Index a = 0; a < r; ++a)
          acc += ci[a] * bj[a];
        zi[j - i] += acc;
      }
    }
  } else {
    z.cross.resize(m, 0);
    z.border.resize(0, 0);
  }
  ++stats_.selected_inversions;
  stats_.selected_inverse_s += seconds_since(t0);
  impl_->selinv = std::move(z);
  return *impl_->selinv;
}

double TikhonovSolver::trace_inverse_penalty(const SelectedInverse& z) const {
  double t = 0.0;
  if (!has_penalty()) {
    for (Eigen::Index j = 0; j < z.band_size; ++j)
      t += z(j, j);
    for (Eigen::Index c = 0; c < z.border.rows(); ++c)
      t += z.border(c, c);
    return t;
  }
  const auto* p = static_cast<const int*>(normal_->band.p);
  const auto* i = static_cast<const int*>(normal_->band.i);
  const double* v = normal_->pen_x.data();
  for (Eigen::Index j = 0; j < static_cast<Eigen::Index>(normal_->band.ncol); ++j)
    for (int q = p[j]; q < p[j + 1]; ++q)
      if (v[q] != 0.0) t += (i[q] == j ? 1.0 : 2.0) * v[q] * z(i[q], j);
  if (border_ > 0 && normal_->C_P.size() > 0)
    t += 2.0 * (normal_->C_P.cwiseProduct(z.cross)).sum() +
         (normal_->D_P.cwiseProduct(z.border)).sum();
  return t;
}

double TikhonovSolver::trace_inverse_normal(const SelectedInverse& z) const {
  // Σ_ij (AᵀA)_ij·Z_ij over the pattern of AᵀA: its band (upper triangle, off-diagonal entries
  // twice), its coupling C with the border and the border block D.
  const auto* p = static_cast<const int*>(normal_->band.p);
  const auto* i = static_cast<const int*>(normal_->band.i);
  const auto* v = static_cast<const double*>(normal_->band.x);
  double t = 0.0;
  for (Eigen::Index j = 0; j < static_cast<Eigen::Index>(normal_->band.ncol); ++j)
    for (int q = p[j]; q < p[j + 1]; ++q)
      if (v[q] != 0.0) t += (i[q] == j ? 1.0 : 2.0) * v[q] * z(i[q], j);
  if (border_ > 0)
    t += 2.0 * (normal_->C.cwiseProduct(z.cross)).sum() + (normal_->D.cwiseProduct(z.border)).sum();
  return t;
}

}  // namespace errsep::core
