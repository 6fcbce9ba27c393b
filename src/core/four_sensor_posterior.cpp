// The posterior estimator of the four-sensor method (four_sensor_posterior.hpp): assembly, the λ
// search (REML, GCV), the posterior covariance from the factor, and the gauge.
//
// Computational gauge.  The data see neither the constant, the line nor the bow of f (with a
// change of η).  Columns of f(x_0) and f(x_{N−1}) are removed (Eq. 11), and so is f(x_c) at the
// middle sample c: with that pin the normal matrix is positive definite for every λ, including 0,
// and has no nearly null direction for round-off to spoil.  A prior needs f itself, not the pinned
// representative f̃ (f̃(x_c) = 0): f = f̃ + β·bow, with β an unknown that the data do not see
// (its column is zero: the bow's effect on the rows is −Qᵀ(O²)/L₀² per position, which η absorbs;
// η̃ = η + β·Qᵀ(O²)/L₀² is what the rows see) and that only the prior ‖L(f̃ + β·bow)‖² holds.
// Eliminating β leaves the marginal prior of f̃, which is what the posterior of anything the data
// see must use.  Finally the bow is removed (f has no bow: the reported gauge): f_G = f̃ − a·bow,
// a = bow·f̃/‖bow‖², and η_G = η̃ − a·Qᵀ(O²)/L₀².  β drops out of every reported quantity.
#include "errsep/core/four_sensor_posterior.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>

#include "errsep/core/four_sensor.hpp"
#include "four_sensor_paths.hpp"

namespace errsep::core {

const char* to_string(Penalty p) {
  switch (p) {
    case Penalty::second_difference:
      return "second_difference";
    case Penalty::identity:
      return "identity";
    case Penalty::none:
      return "none";
  }
  return "unknown";
}

std::optional<Penalty> penalty_from_string(std::string_view s) {
  for (auto p : {Penalty::second_difference, Penalty::identity, Penalty::none})
    if (s == to_string(p)) return p;
  return std::nullopt;
}

Eigen::Matrix<double, 4, 2> reading_combinations(const FourSensorConfig& cfg) {
  const auto O = cfg.offsets_mm();
  Eigen::Matrix<double, 4, 2> X;
  for (int j = 0; j < 4; ++j)
    X.row(j) << 1.0, O[static_cast<std::size_t>(j)];
  const Eigen::JacobiSVD<Eigen::Matrix<double, 4, 2>> svd(X, Eigen::ComputeFullU);
  return svd.matrixU().rightCols<2>();
}

namespace {

int middle_sample(const FourSensorConfig& cfg) {
  return (cfg.N - 1) / 2;
}

// Qᵀ(O²)/L₀²: how η changes when c·bow is added to f (per unit c).
Eigen::Vector2d bow_eta(const FourSensorConfig& cfg, const Eigen::Matrix<double, 4, 2>& Q) {
  const auto O = cfg.offsets_mm();
  Eigen::Vector4d o2;
  for (int j = 0; j < 4; ++j)
    o2(j) = O[static_cast<std::size_t>(j)] * O[static_cast<std::size_t>(j)];
  const double L0 = cfg.reference_length_mm();
  return Q.transpose() * o2 / (L0 * L0);
}

}  // namespace

PinnedSystem assemble_pinned_system(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                    bool with_bow_unknown) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  const int N = cfg.N, P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("sensor outputs are " + std::to_string(m_um.rows()) + "x" +
                                std::to_string(m_um.cols()) + ", configuration needs " +
                                std::to_string(P) + "x4 (P = N - s2 - s3 - s4 slide positions)");
  PinnedSystem sys;
  sys.pinned_middle = middle_sample(cfg);
  sys.f_index.assign(static_cast<std::size_t>(N), -1);
  int m = 0;
  for (int i = 1; i < N - 1; ++i)
    if (i != sys.pinned_middle) sys.f_index[static_cast<std::size_t>(i)] = m++;
  sys.band_unknowns = m;
  sys.border = with_bow_unknown ? 3 : 2;
  const Eigen::Matrix<double, 4, 2> Q = reading_combinations(cfg);
  const auto k = cfg.offsets_samples();
  sys.b.resize(2 * P);
  for (int n = 0; n < P; ++n)
    for (int r = 0; r < 2; ++r)
      sys.b(2 * n + r) = Q.col(r).dot(m_um.row(n).transpose());
  // A written column by column into its compressed storage (no triplets: at N = 10⁶ the triplet
  // list and its sort were a quarter of the set-up's page faults).  Row 2n + r holds Q(j, r) in
  // the column of f̃(x_{n + k_j}) for each sensor j and 1 in the column of η̃_r.  The column of
  // f̃(x_i) has rows 2n, 2n + 1 for n = i − k_j (j from the last sensor: rows ascending); the
  // offsets increase strictly, so no two entries share a row.
  const int cols = m + sys.border;
  std::vector<int> outer(static_cast<std::size_t>(cols) + 1, 0);
  for (int i = 0; i < N; ++i) {
    const int col = sys.f_index[static_cast<std::size_t>(i)];
    if (col < 0) continue;
    int rows = 0;
    for (int j = 0; j < 4; ++j) {
      const int n = i - k[static_cast<std::size_t>(j)];
      if (n >= 0 && n < P) rows += 2;
    }
    outer[static_cast<std::size_t>(col) + 1] = rows;
  }
  outer[static_cast<std::size_t>(m) + 1] = P;  // η̃_1, η̃_2: every reading
  outer[static_cast<std::size_t>(m) + 2] = P;
  for (std::size_t c = 0; c < static_cast<std::size_t>(cols); ++c)
    outer[c + 1] += outer[c];
  sys.A.resize(2 * P, cols);  // the bow unknown β, if any, has an empty column
  sys.A.data().resize(outer.back());
  std::copy(outer.begin(), outer.end(), sys.A.outerIndexPtr());
  int* inner = sys.A.innerIndexPtr();
  double* val = sys.A.valuePtr();
  for (int i = 0; i < N; ++i) {
    const int col = sys.f_index[static_cast<std::size_t>(i)];
    if (col < 0) continue;
    int q = outer[static_cast<std::size_t>(col)];
    for (int j = 3; j >= 0; --j) {
      const int n = i - k[static_cast<std::size_t>(j)];
      if (n < 0 || n >= P) continue;
      for (int r = 0; r < 2; ++r, ++q) {
        inner[q] = 2 * n + r;
        val[q] = Q(j, r);
      }
    }
  }
  for (int r = 0; r < 2; ++r) {
    int q = outer[static_cast<std::size_t>(m + r)];
    for (int n = 0; n < P; ++n, ++q) {
      inner[q] = 2 * n + r;
      val[q] = 1.0;
    }
  }
  return sys;
}

Eigen::SparseMatrix<double> penalty_operator(const FourSensorConfig& cfg, Penalty penalty,
                                             const PinnedSystem& sys) {
  if (penalty == Penalty::none || sys.border < 3)
    throw std::invalid_argument("penalty_operator: needs a prior and the bow unknown");
  const int N = cfg.N, m = sys.band_unknowns, beta = m + 2;
  const Eigen::VectorXd bow = reference_bow(cfg);
  // L acts on f = f̃ + β·bow (ends zero): each row of L as coefficients on the unknowns.
  std::vector<Eigen::Triplet<double>> lt;
  int rows = 0;
  auto add_row = [&](const std::vector<std::pair<int, double>>& f_coef) {
    double on_beta = 0.0;
    for (const auto& [i, c] : f_coef) {
      const int col = sys.f_index[static_cast<std::size_t>(i)];
      if (col >= 0) lt.emplace_back(rows, col, c);
      on_beta += c * bow(i);
    }
    if (on_beta != 0.0) lt.emplace_back(rows, beta, on_beta);
    ++rows;
  };
  if (penalty == Penalty::second_difference) {
    for (int i = 0; i + 2 < N; ++i)
      add_row({{i, 1.0}, {i + 1, -2.0}, {i + 2, 1.0}});
  } else {
    for (int i = 1; i < N - 1; ++i)
      add_row({{i, 1.0}});
  }
  Eigen::SparseMatrix<double> L(rows, m + sys.border);
  L.setFromTriplets(lt.begin(), lt.end());
  L.makeCompressed();
  return L;
}

// ---------------------------------------------------------------------------------------------
// Covariance of functionals.

struct FourSensorCovariance::Parts {
  FourSensorConfig cfg;
  std::unique_ptr<TikhonovSolver> solver;  // factorised at the result's λ
  std::vector<int> f_index;
  int m = 0;      // band unknowns; η̃ at m, m + 1
  int n_all = 0;  // all unknowns (β included)
  double sigma2 = 0.0;
  Eigen::Vector4d w_S, w_g;       // S = w_S·r, γ [µm/mm] = w_g·r, r = m − f(x + O) − e
  Eigen::Matrix<double, 4, 2> E;  // e = E·η
  Eigen::VectorXd bow;            // N
  Eigen::Vector2d n_eta;          // Qᵀ(O²)/L₀²
  double gn = 0.0;                // Σ bow²
  Eigen::SparseMatrix<double> L;  // the prior's operator (empty without a prior)
  double lambda = 0.0;
  Eigen::Matrix4d span_projector;  // onto span{1, O}: the noise S and γ take directly
  // add_low_rank: G_S·R, G_γ·R, G_f·R with R·Rᵀ = K (columns of the square root of K).
  Eigen::MatrixXd lr_S, lr_g, lr_f;

  // Coefficients on the unknowns (and n·h of the full vector) of the functional
  // Σ a_n S_n + Σ b_n γ_n + Σ c_i f_i, and its direct noise part Σ‖v_n‖².
  void functional(const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& c,
                  Eigen::VectorXd& h, double& nh, double& noise) const {
    const int P = cfg.positions(), N = cfg.N;
    const auto k = cfg.offsets_samples();
    h = Eigen::VectorXd::Zero(n_all);
    nh = 0.0;
    noise = 0.0;
    for (int n = 0; n < P; ++n) {
      const double an = a.size() ? a(n) : 0.0, bn = b.size() ? b(n) : 0.0;
      if (an == 0.0 && bn == 0.0) continue;
      const Eigen::Vector4d v = an * w_S + 1e-3 * bn * w_g;  // γ in rad = 1e-3 · µm/mm
      noise += v.squaredNorm();
      for (int j = 0; j < 4; ++j) {
        const int i = n + k[static_cast<std::size_t>(j)];
        const int col = f_index[static_cast<std::size_t>(i)];
        if (col >= 0) h(col) -= v(j);
        nh -= v(j) * bow(i);
      }
      const Eigen::Vector2d ev = E.transpose() * v;
      h.segment<2>(m) -= ev;
      nh -= ev.dot(n_eta);
    }
    for (int i = 0; i < N && c.size(); ++i) {
      if (c(i) == 0.0) continue;
      const int col = f_index[static_cast<std::size_t>(i)];
      if (col >= 0) h(col) += c(i);
      nh += c(i) * bow(i);
    }
  }
  // h − a·g with a = n·h/g·n: the functional of the gauge-fixed unknowns (see the file comment).
  void to_gauge(Eigen::VectorXd& h, double nh) const {
    const double a = nh / gn;
    for (int i = 0; i < cfg.N; ++i) {
      const int col = f_index[static_cast<std::size_t>(i)];
      if (col >= 0) h(col) -= a * bow(i);
    }
  }
};

FourSensorCovariance::FourSensorCovariance(std::unique_ptr<Parts> parts) : p_(std::move(parts)) {}
FourSensorCovariance::~FourSensorCovariance() = default;

double FourSensorCovariance::variance(const Eigen::VectorXd& a_S, const Eigen::VectorXd& b_gamma,
                                      const Eigen::VectorXd& c_f) {
  const int P = p_->cfg.positions(), N = p_->cfg.N;
  if ((a_S.size() && a_S.size() != P) || (b_gamma.size() && b_gamma.size() != P) ||
      (c_f.size() && c_f.size() != N))
    throw std::invalid_argument("FourSensorCovariance::variance: coefficient vectors need " +
                                std::to_string(P) + " (S, gamma) and " + std::to_string(N) +
                                " (f) entries");
  Eigen::VectorXd h;
  double nh = 0.0, noise = 0.0;
  p_->functional(a_S, b_gamma, c_f, h, nh, noise);
  p_->to_gauge(h, nh);
  double extra = 0.0;
  if (p_->lr_S.cols() > 0) {
    Eigen::VectorXd t = Eigen::VectorXd::Zero(p_->lr_S.cols());
    if (a_S.size()) t += p_->lr_S.transpose() * a_S;
    if (b_gamma.size()) t += p_->lr_g.transpose() * b_gamma;
    if (c_f.size()) t += p_->lr_f.transpose() * c_f;
    extra = t.squaredNorm();
  }
  return p_->sigma2 * (noise + p_->solver->inverse_quadratic_form(h)) + extra;
}

void FourSensorCovariance::add_low_rank(const Eigen::MatrixXd& G_S, const Eigen::MatrixXd& G_gamma,
                                        const Eigen::MatrixXd& G_f, const Eigen::MatrixXd& K) {
  const int P = p_->cfg.positions(), N = p_->cfg.N;
  const Eigen::Index k = K.rows();
  if (K.cols() != k || G_S.rows() != P || G_gamma.rows() != P || G_f.rows() != N ||
      G_S.cols() != k || G_gamma.cols() != k || G_f.cols() != k)
    throw std::invalid_argument(
        "FourSensorCovariance::add_low_rank: G_S, G_gamma need P = " + std::to_string(P) +
        " rows, G_f N = " + std::to_string(N) + ", all k columns for a k x k K");
  if (k == 0) return;
  // R with R·Rᵀ = K from the eigendecomposition (K may be singular).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (K + K.transpose()));
  const Eigen::MatrixXd R =
      es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  auto append = [](Eigen::MatrixXd& to, const Eigen::MatrixXd& cols) {
    Eigen::MatrixXd out(cols.rows(), to.cols() + cols.cols());
    if (to.cols() > 0) out.leftCols(to.cols()) = to;
    out.rightCols(cols.cols()) = cols;
    to = std::move(out);
  };
  append(p_->lr_S, G_S * R);
  append(p_->lr_g, G_gamma * R);
  append(p_->lr_f, G_f * R);
}

void FourSensorCovariance::sample(std::uint64_t seed, Eigen::VectorXd& dS_um,
                                  Eigen::VectorXd& dgamma_rad) {
  Parts& p = *p_;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  const double sigma = std::sqrt(p.sigma2);
  const TikhonovSolver& s = *p.solver;
  Eigen::VectorXd e1(s.A().rows());
  for (Eigen::Index i = 0; i < e1.size(); ++i)
    e1(i) = nd(rng);
  Eigen::VectorXd rhs = s.A().transpose() * (sigma * e1);
  if (p.L.rows() > 0) {
    Eigen::VectorXd e2(p.L.rows());
    for (Eigen::Index i = 0; i < e2.size(); ++i)
      e2(i) = nd(rng);
    rhs += (p.lambda * sigma) * (p.L.transpose() * e2);
  }
  const Eigen::VectorXd dx = p.solver->solve_normal(rhs);
  // The gauge: d f_G = d f̃ − a·bow, d η_G = d η̃ − a·n_η, a = bow·d f̃/‖bow‖².
  const int N = p.cfg.N, P = p.cfg.positions();
  Eigen::VectorXd df = Eigen::VectorXd::Zero(N);
  for (int i = 0; i < N; ++i) {
    const int col = p.f_index[static_cast<std::size_t>(i)];
    if (col >= 0) df(i) = dx(col);
  }
  const double a = p.bow.dot(df) / p.gn;
  df -= a * p.bow;
  const Eigen::Vector4d de = p.E * (dx.segment<2>(p.m) - a * p.n_eta);
  const auto k = p.cfg.offsets_samples();
  dS_um.resize(P);
  dgamma_rad.resize(P);
  for (int n = 0; n < P; ++n) {
    Eigen::Vector4d eps;
    for (int j = 0; j < 4; ++j)
      eps(j) = sigma * nd(rng);
    Eigen::Vector4d r = -p.span_projector * eps;  // the truth's own noise, unknown to the data
    for (int j = 0; j < 4; ++j)
      r(j) -= df(n + k[static_cast<std::size_t>(j)]) + de(j);
    dS_um(n) = p.w_S.dot(r);
    dgamma_rad(n) = 1e-3 * p.w_g.dot(r);
  }
  if (p.lr_S.cols() > 0) {  // the added low-rank part: G·R·z, z standard normal
    Eigen::VectorXd z(p.lr_S.cols());
    for (Eigen::Index i = 0; i < z.size(); ++i)
      z(i) = nd(rng);
    dS_um += p.lr_S * z;
    dgamma_rad += p.lr_g * z;
  }
}

Eigen::MatrixXd FourSensorCovariance::covariance_S(const std::vector<int>& positions) {
  const int P = p_->cfg.positions();
  const auto q = static_cast<Eigen::Index>(positions.size());
  Eigen::MatrixXd H(p_->n_all, q), MH(p_->n_all, q);
  for (Eigen::Index j = 0; j < q; ++j) {
    const int n = positions[static_cast<std::size_t>(j)];
    if (n < 0 || n >= P)
      throw std::invalid_argument("FourSensorCovariance::covariance_S: position " +
                                  std::to_string(n) + " outside 0.." + std::to_string(P - 1));
    Eigen::VectorXd a = Eigen::VectorXd::Zero(P), h;
    a(n) = 1.0;
    double nh = 0.0, noise = 0.0;
    p_->functional(a, {}, {}, h, nh, noise);
    p_->to_gauge(h, nh);
    H.col(j) = h;
    MH.col(j) = p_->solver->solve_normal(h);
  }
  Eigen::MatrixXd V = H.transpose() * MH;
  V.diagonal().array() += p_->w_S.squaredNorm();  // the readings' own noise, independent per n
  V *= p_->sigma2;
  if (p_->lr_S.cols() > 0) {
    Eigen::MatrixXd G(q, p_->lr_S.cols());
    for (Eigen::Index j = 0; j < q; ++j)
      G.row(j) = p_->lr_S.row(positions[static_cast<std::size_t>(j)]);
    V += G * G.transpose();
  }
  return V;
}

Eigen::MatrixXd FourSensorCovariance::covariance_S_with(const Eigen::MatrixXd& a_S) {
  const Parts& p = *p_;
  const int P = p.cfg.positions(), N = p.cfg.N;
  if (a_S.rows() != P)
    throw std::invalid_argument("FourSensorCovariance::covariance_S_with: coefficients have " +
                                std::to_string(a_S.rows()) + " rows, need " + std::to_string(P));
  const auto k = p.cfg.offsets_samples();
  Eigen::VectorXd g = Eigen::VectorXd::Zero(p.n_all);  // the bow that to_gauge removes
  for (int i = 0; i < N; ++i) {
    const int col = p.f_index[static_cast<std::size_t>(i)];
    if (col >= 0) g(col) = p.bow(i);
  }
  const Eigen::Vector2d ew = p.E.transpose() * p.w_S;
  const double ww = p.w_S.squaredNorm();
  Eigen::MatrixXd out(P, a_S.cols());
  for (Eigen::Index j = 0; j < a_S.cols(); ++j) {
    Eigen::VectorXd h;
    double nh = 0.0, noise = 0.0;
    p.functional(a_S.col(j), {}, {}, h, nh, noise);
    p.to_gauge(h, nh);
    const Eigen::VectorXd y = p.solver->solve_normal(h);
    const double gy = g.dot(y);
    // t_nᵀy for t_n = h_n − (n·h_n/g·n)·g, h_n the coefficients of S(x_n) as functional() forms
    // them (at most 4 samples of f and η̃), and the readings' own noise, independent per n.
    for (int n = 0; n < P; ++n) {
      double hy = -ew.dot(y.segment<2>(p.m)), nhn = -ew.dot(p.n_eta);
      for (int q = 0; q < 4; ++q) {
        const int i = n + k[static_cast<std::size_t>(q)];
        const int col = p.f_index[static_cast<std::size_t>(i)];
        if (col >= 0) hy -= p.w_S(q) * y(col);
        nhn -= p.w_S(q) * p.bow(i);
      }
      out(n, j) = p.sigma2 * (a_S(n, j) * ww + hy - nhn / p.gn * gy);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// λ search.

namespace {

struct Criterion {
  double value = std::numeric_limits<double>::infinity();
  bool ok = false;
  std::string rejected;  ///< why λ could not be evaluated (the factor's failure), if so
};

// REML, σ held at σ̂ (issue 15: "σ fixed at the σ̂ of the redundant equations"):
//   −2 log L_R(λ) = (‖b − Ax‖² + λ²xᵀPx)/σ̂² + log det(AᵀA + λ²P) − r·log λ² + const,
// r = rank P (the unknowns that carry the prior).  log det P and the terms of the fixed effects
// (η̃) that do not depend on λ are constants.
Criterion reml_at(TikhonovSolver& s, const Eigen::VectorXd& Atb, double bb, double sigma2, int rank,
                  double lambda) {
  Criterion c;
  // ‖b − Ax‖² + λ²xᵀPx = bᵀb − (Aᵀb)ᵀM⁻¹(Aᵀb) at x = M⁻¹Aᵀb: the forward substitution alone,
  // no back substitution and no x.
  double q = 0.0;
  if (s.factorize_and_quadratic_form(lambda, Atb, q) != SolverStatus::success) {
    c.rejected = s.failure().message();
    return c;
  }
  const double l2 = lambda * lambda;
  c.value = std::max(0.0, bb - q) / sigma2 + s.log_det() - rank * std::log(l2);
  c.ok = std::isfinite(c.value);
  return c;
}

// GCV: n·‖b − Ax‖²/(n − edf)², edf = tr(M⁻¹AᵀA) from the selected inverse.
Criterion gcv_at(TikhonovSolver& s, const Eigen::VectorXd& b, const Eigen::VectorXd& Atb,
                 double lambda) {
  Criterion c;
  Eigen::VectorXd x;
  if (s.factorize_and_solve(lambda, Atb, x) != SolverStatus::success) {
    c.rejected = s.failure().message();
    return c;
  }
  const double rss = (s.A() * x - b).squaredNorm();
  const double edf = s.trace_inverse_normal(s.selected_inverse());
  const auto n = static_cast<double>(b.size());
  if (!(n - edf > 0)) return c;
  c.value = n * rss / ((n - edf) * (n - edf));
  c.ok = std::isfinite(c.value);
  return c;
}

struct SearchOutcome {
  double lambda = 0.0;
  /// The minimum is not bracketed: no finite criterion was evaluated on one side of the chosen λ
  /// (the chosen λ is at an end of the range, or every λ beyond it on that side was refused).
  bool at_edge = false;
  /// at_edge because of refused λ: the criterion still falls at the last λ the factorisation
  /// accepted, and the λ beyond it (toward which it falls) were refused (issue 15, N = 10⁶).
  bool at_refused_edge = false;
  int worker_factorizations = 0;  ///< done by the worker threads (not in the solver's stats)
  std::vector<double> grid_lambda, grid_criterion;  ///< the grid's finite points
  std::vector<std::string> rejected;                ///< λ that could not be evaluated, and why
};

// Grid in log λ (on `threads` threads, each with its own factor), then a refinement around the
// best point: its two neighbours at half the spacing, evaluated at once (one on a worker when
// there are two threads), the best of the three kept and the spacing halved, refine_iterations
// times.  For a unimodal criterion each step halves the bracket for the wall time of one
// evaluation on two threads (golden section: 0.618 per evaluation, which cannot run in parallel).
template <class F>
SearchOutcome minimise_over_lambda(TikhonovSolver& solver, const LambdaSearchOptions& o, F&& crit) {
  const double lmax = solver.sigma_max_bound() * std::pow(10.0, o.decades_above);
  const double lmin = solver.sigma_max_bound() * std::pow(10.0, -o.decades_below);
  const int count = o.count;
  std::vector<double> grid(static_cast<std::size_t>(count)), val(grid.size());
  for (int i = 0; i < count; ++i)
    grid[static_cast<std::size_t>(i)] =
        std::log10(lmin) + (std::log10(lmax) - std::log10(lmin)) * i / (count - 1);
  const int threads = std::max(1, std::min(o.threads, count));
  std::vector<std::unique_ptr<TikhonovSolver>> workers;
  for (int t = 1; t < threads; ++t)
    workers.push_back(solver.worker());
  // Runs job(t, solver_t) for t = 0 … n−1, t > 0 on worker threads.
  auto in_parallel = [&](int n, auto&& job) {
    std::vector<std::thread> pool;
    std::exception_ptr err;
    for (int t = 1; t < n; ++t)
      pool.emplace_back([&, t] {
        try {
          job(t, *workers[static_cast<std::size_t>(t - 1)]);
        } catch (...) {
          err = std::current_exception();
        }
      });
    job(0, solver);
    for (auto& th : pool)
      th.join();
    if (err) std::rethrow_exception(err);
  };
  // A refused factorisation (on long scans AᵀA + λ²P is singular to working precision at some λ:
  // the factor reports the pivot it lost, FactorFailure) or a non-finite criterion counts as +∞
  // and is recorded: NaN compares false both ways and would stall the minimum at the first grid
  // point.
  // Why a λ was rejected goes into `why` (one slot per evaluation: the threads write apart).
  auto eval = [&](TikhonovSolver& s, double log_lambda, std::string& why) {
    Criterion c = crit(s, std::pow(10.0, log_lambda));
    if (!c.rejected.empty()) why = std::move(c.rejected);
    return c.ok ? c.value : std::numeric_limits<double>::infinity();
  };
  std::vector<std::string> why(grid.size());
  in_parallel(threads, [&](int t, TikhonovSolver& s) {
    for (int i = t; i < count; i += threads)
      val[static_cast<std::size_t>(i)] =
          eval(s, grid[static_cast<std::size_t>(i)], why[static_cast<std::size_t>(i)]);
  });
  SearchOutcome out;
  std::vector<bool> refused(grid.size());
  for (std::size_t q = 0; q < grid.size(); ++q)
    refused[q] = !why[q].empty();
  for (auto& w : why)
    if (!w.empty()) out.rejected.push_back(std::move(w));
  for (std::size_t q = 0; q < grid.size(); ++q)
    if (std::isfinite(val[q])) {
      out.grid_lambda.push_back(std::pow(10.0, grid[q]));
      out.grid_criterion.push_back(val[q]);
    }
  const auto best = static_cast<int>(std::min_element(val.begin(), val.end()) - val.begin());
  if (!std::isfinite(val[static_cast<std::size_t>(best)]))
    throw std::runtime_error("lambda search: the factorisation failed at every lambda of the grid");
  // The minimum is at the edge when the grid's best is an end of the range (the collapse rule
  // reads it), or when on one side of it the grid has no accepted λ but a refused one: the
  // criterion may still fall beyond the last λ the factorisation accepted (at N = 10⁶ REML falls
  // up to the largest accepted λ and every larger one is refused).  Judged on the grid, as the
  // range's end is: the refinement only halves the spacing around the grid's best.
  const bool range_edge = best == 0 || best == count - 1;
  bool below = false, above = false, refused_below = false, refused_above = false;
  for (int q = 0; q < count; ++q) {
    const auto u = static_cast<std::size_t>(q);
    const bool finite = std::isfinite(val[u]);
    if (q < best) {
      below = below || finite;
      refused_below = refused_below || refused[u];
    } else if (q > best) {
      above = above || finite;
      refused_above = refused_above || refused[u];
    }
  }
  out.at_refused_edge = (!below && refused_below) || (!above && refused_above);
  out.at_edge = range_edge || out.at_refused_edge;
  double best_l = grid[static_cast<std::size_t>(best)],
         best_v = val[static_cast<std::size_t>(best)];
  double h = grid[1] - grid[0];
  const double lo = grid.front(), hi = grid.back();
  for (int it = 0; it < o.refine_iterations; ++it) {
    h *= 0.5;
    const double at[2] = {best_l - h, best_l + h};
    double v[2] = {std::numeric_limits<double>::infinity(),
                   std::numeric_limits<double>::infinity()};
    std::string w[2];
    auto job = [&](int t, TikhonovSolver& s) {
      for (int i = t; i < 2; i += std::min(threads, 2))
        if (at[i] >= lo - 1e-12 && at[i] <= hi + 1e-12)  // inside the range only
          v[i] = eval(s, at[i], w[i]);
    };
    in_parallel(std::min(threads, 2), job);
    for (int i = 0; i < 2; ++i) {
      if (v[i] < best_v) best_v = v[i], best_l = at[i];
      if (!w[i].empty()) out.rejected.push_back(std::move(w[i]));
    }
  }
  for (const auto& w : workers)
    out.worker_factorizations += w->stats().factorizations;
  out.lambda = std::pow(10.0, best_l);
  return out;
}

// Least-squares line S + O·γ through the four residuals: the weights of S and γ (µm/mm).
void line_weights(const FourSensorConfig& cfg, Eigen::Vector4d& w_S, Eigen::Vector4d& w_g) {
  const auto O = cfg.offsets_mm();
  Eigen::Matrix<double, 4, 2> X;
  for (int j = 0; j < 4; ++j)
    X.row(j) << 1.0, O[static_cast<std::size_t>(j)];
  const Eigen::Matrix<double, 2, 4> W = (X.transpose() * X).inverse() * X.transpose();
  w_S = W.row(0).transpose();
  w_g = W.row(1).transpose();
}

}  // namespace

// ---------------------------------------------------------------------------------------------

FourSensorResult separate_posterior(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                    const FourSensorOptions& opts, double known_sigma_um) {
  const auto t0 = std::chrono::steady_clock::now();
  const int N = cfg.N, P = cfg.positions();
  FourSensorResult res;
  res.config = cfg;
  res.rule = opts.rule;
  res.estimator = Estimator::posterior;
  res.gauge = CurvatureGauge::reference_without_curvature;

  res.redundancy_dof = 2 * P - (N - 1);
  if (res.redundancy_dof < 1)
    throw std::invalid_argument("N = " + std::to_string(N) +
                                " leaves no redundant readings to estimate the noise from");
  const bool prior = opts.penalty != Penalty::none && opts.rule != LambdaRule::least_squares;
  // σ̂ from the redundancy: the unregularised fit leaves 2P rows explained by N − 1 unknowns.
  // With a prior and two threads it runs beside the prior's assembly (they share nothing but
  // the readings): at N = 10⁶ each is ~1 s.
  std::unique_ptr<TikhonovSolver> ls;
  PinnedSystem ls_sys;
  double sigma_um = 0.0;
  auto least_squares = [&] {
    ls_sys = assemble_pinned_system(cfg, m_um, false);
    ls = std::make_unique<TikhonovSolver>(std::move(ls_sys.A), ls_sys.border);
    if (ls->factorize(0.0) != SolverStatus::success)
      throw std::runtime_error(
          "the four-sensor system is rank-deficient beyond the gauge (spacings s = (" +
          std::to_string(cfg.s2) + ", " + std::to_string(cfg.s3) + ", " + std::to_string(cfg.s4) +
          ") with N = " + std::to_string(N) + "): " + ls->failure().message());
    const Eigen::VectorXd x_ls = ls->solve(ls_sys.b);
    sigma_um = known_sigma_um > 0.0
                   ? known_sigma_um
                   : std::sqrt((ls->A() * x_ls - ls_sys.b).squaredNorm() / res.redundancy_dof);
  };
  std::exception_ptr ls_error;
  std::thread ls_thread;
  if (prior && opts.search.threads >= 2)
    ls_thread = std::thread([&] {
      try {
        least_squares();
      } catch (...) {
        ls_error = std::current_exception();
      }
    });
  else
    least_squares();
  auto join_least_squares = [&] {
    if (ls_thread.joinable()) ls_thread.join();
    if (ls_error) std::rethrow_exception(ls_error);
  };

  std::unique_ptr<TikhonovSolver> solver;
  PinnedSystem sys;
  FourSensorCovariance::Parts parts;
  int extra_factorizations = 0;
  double lambda = 0.0;
  double rejected_lambda = 0.0;  // the rule's λ when the collapse rule rejects the prior
  bool refused_edge = false;     // the rule's minimum sits next to refused λ (not bracketed)
  double rule_lambda = 0.0;      // the λ the rule chose (before a collapse)
  res.penalty = prior ? opts.penalty : Penalty::none;
  double sigma2 = 0.0;
  if (prior) {
    try {
      sys = assemble_pinned_system(cfg, m_um, true);
      parts.L = penalty_operator(cfg, opts.penalty, sys);
      Eigen::SparseMatrix<double> Pm = parts.L.transpose() * parts.L;
      Pm.prune(0.0);
      solver = std::make_unique<TikhonovSolver>(std::move(sys.A), sys.border, Pm);
    } catch (...) {
      if (ls_thread.joinable()) ls_thread.join();
      throw;
    }
  }
  join_least_squares();
  res.sigma_um = sigma_um;
  sigma2 = std::max(res.sigma_um * res.sigma_um, 1e-30);
  const Eigen::VectorXd b = ls_sys.b;  // kept: ls_sys moves into the result after a collapse
  if (prior) {
    const Eigen::VectorXd Atb = solver->A().transpose() * b;
    const double bb = b.squaredNorm();
    const int rank = sys.band_unknowns + 1;  // f̃ and β carry the prior
    switch (opts.rule) {
      case LambdaRule::reml: {
        const auto o = minimise_over_lambda(*solver, opts.search, [&](TikhonovSolver& s, double l) {
          return reml_at(s, Atb, bb, sigma2, rank, l);
        });
        lambda = o.lambda;
        res.lambda_at_edge = o.at_edge;
        refused_edge = o.at_refused_edge;
        extra_factorizations = o.worker_factorizations;
        res.lambda_grid = o.grid_lambda;
        res.lambda_criterion = o.grid_criterion;
        res.lambda_rejected = o.rejected;
        break;
      }
      case LambdaRule::gcv: {
        const auto o = minimise_over_lambda(*solver, opts.search, [&](TikhonovSolver& s, double l) {
          return gcv_at(s, b, Atb, l);
        });
        lambda = o.lambda;
        res.lambda_at_edge = o.at_edge;
        refused_edge = o.at_refused_edge;
        extra_factorizations = o.worker_factorizations;
        res.lambda_grid = o.grid_lambda;
        res.lambda_criterion = o.grid_criterion;
        res.lambda_rejected = o.rejected;
        break;
      }
      case LambdaRule::lcurve: {
        LCurveOptions lo = opts.lcurve;
        if (lo.lambda_max <= 0)
          lo.lambda_max = solver->sigma_max_bound() * std::pow(10.0, opts.search.decades_above);
        if (lo.lambda_min <= 0)
          lo.lambda_min = solver->sigma_max_bound() * std::pow(10.0, -opts.search.decades_below);
        res.lcurve = lcurve_corner(*solver, b, lo);
        lambda = res.lcurve.lambda_corner;
        if (!res.lcurve.has_corner) {
          const double delta = res.sigma_um * std::sqrt(2.0 * P);
          lambda = discrepancy_lambda(*solver, b, opts.discrepancy_tau * delta, lo.lambda_min,
                                      lo.lambda_max);
          res.lambda_fallback = LambdaFallback::discrepancy;
        }
        break;
      }
      case LambdaRule::discrepancy: {
        const double delta = res.sigma_um * std::sqrt(2.0 * P);
        lambda = discrepancy_lambda(
            *solver, b, opts.discrepancy_tau * delta,
            solver->sigma_max_bound() * std::pow(10.0, -opts.search.decades_below),
            solver->sigma_max_bound() * std::pow(10.0, opts.search.decades_above));
        break;
      }
      case LambdaRule::fixed:
        lambda = opts.fixed_lambda;
        break;
      case LambdaRule::least_squares:
        break;
    }
  }
  rule_lambda = lambda;
  // The least-squares separation's selected inverse is what its u needs after a collapse: with
  // two threads it is formed beside the final factorisation and the edf of the prior (at
  // N = 10⁶ both ~0.5 s; long scans are where collapses happen), and dropped if not used.
  std::thread ls_selinv;
  if (prior && opts.compute_uncertainty && opts.search.threads >= 2)
    ls_selinv = std::thread([&] {
      try {
        ls->selected_inverse();
      } catch (...) {
        ls_error = std::current_exception();
      }
    });
  try {
    // The search's last factorisation on this thread may already be the chosen λ's (the same
    // factor factorize() would make): at N = 10⁶ a factorisation saved is 0.2 s.
    if (prior && !(solver->factorized() && solver->lambda() == lambda) &&
        solver->factorize(lambda) != SolverStatus::success)
      throw std::runtime_error("factorisation failed at the chosen " + solver->failure().message());
    if (prior) {
      const SelectedInverse& z = solver->selected_inverse();
      // tr(M⁻¹AᵀA) summed directly, not n − λ²·tr(M⁻¹P): on long scans the difference loses
      // edf to cancellation (tikhonov_solver.hpp), and the collapse rule below reads it.
      res.edf = solver->trace_inverse_normal(z);
      res.edf_f = res.edf - 2.0;  // η̃ is not penalised: 2 of them
      // A collapse: the prior swallowed f (issue 15).  The λ at the top of the range, or f with
      // (almost) no degrees of freedom left: S would carry f's amplitude with a small stated u.
      const bool top_edge = res.lambda_at_edge && lambda > solver->sigma_max_bound();
      if ((opts.rule == LambdaRule::reml || opts.rule == LambdaRule::gcv ||
           opts.rule == LambdaRule::lcurve) &&
          (top_edge || res.edf_f < opts.collapse_edf)) {
        res.lambda_fallback = LambdaFallback::collapse_least_squares;
        res.penalty = Penalty::none;
        rejected_lambda = lambda;
      }
    }
  } catch (...) {
    if (ls_selinv.joinable()) ls_selinv.join();
    throw;
  }
  if (ls_selinv.joinable()) ls_selinv.join();
  if (ls_error) std::rethrow_exception(ls_error);
  const bool use_ls = res.penalty == Penalty::none;
  if (use_ls) {
    solver = std::move(ls);
    lambda = 0.0;
    parts.L.resize(0, 0);
    sys = std::move(ls_sys);
    sys.A.resize(0, 0);
    if (!prior) {
      res.edf = static_cast<double>(N - 1);
      res.edf_f = res.edf - 2.0;
    }
  } else {
    ls.reset();
  }
  res.lambda = lambda;

  // The solution in the gauge of the report: f̃ → f_G = f̃ − a·bow, η̃ → η_G = η̃ − a·n_η.
  const Eigen::Matrix<double, 4, 2> Q = reading_combinations(cfg);
  const Eigen::VectorXd x = solver->solve(b);
  res.residual_norm = (solver->A() * x - b).norm();
  res.solution_norm = std::sqrt(std::max(0.0, x.dot(solver->apply_penalty(x))));
  parts.cfg = cfg;
  parts.lambda = lambda;
  {
    const Eigen::Matrix<double, 4, 2> Qc = Q;
    parts.span_projector = Eigen::Matrix4d::Identity() - Qc * Qc.transpose();
  }
  parts.f_index = sys.f_index;
  parts.m = sys.band_unknowns;
  parts.n_all = static_cast<int>(solver->A().cols());
  parts.sigma2 = sigma2;
  line_weights(cfg, parts.w_S, parts.w_g);
  {
    // e = (0, e2, e3, 0) with Qᵀe = η: the constants of S and γ set by e_1 = e_4 = 0, as
    // Eq. (19) leaves them.
    Eigen::Matrix2d K;
    K << Q(1, 0), Q(2, 0), Q(1, 1), Q(2, 1);
    const Eigen::Matrix2d Ki = K.inverse();
    parts.E.setZero();
    parts.E.row(1) = Ki.row(0);
    parts.E.row(2) = Ki.row(1);
  }
  parts.bow = reference_bow(cfg);
  parts.n_eta = bow_eta(cfg, Q);
  parts.gn = parts.bow.squaredNorm();
  Eigen::VectorXd f = Eigen::VectorXd::Zero(N);
  for (int i = 0; i < N; ++i) {
    const int col = parts.f_index[static_cast<std::size_t>(i)];
    if (col >= 0) f(i) = x(col);
  }
  const double a = parts.bow.dot(f) / parts.gn;
  f -= a * parts.bow;
  const Eigen::Vector2d eta = x.segment<2>(parts.m) - a * parts.n_eta;
  const Eigen::Vector4d e = parts.E * eta;
  res.f_um = f;
  res.e_um = e;
  res.delta_e_um = combination_matrix(cfg) * e;
  res.f_x_mm = Eigen::VectorXd::LinSpaced(N, 0.0, (N - 1) * cfg.dx_mm);
  res.x_mm = res.f_x_mm.head(P);
  res.S_um.resize(P);
  res.gamma_rad.resize(P);
  res.sensor_residual_um.resize(P, 4);
  const auto k = cfg.offsets_samples();
  const auto O = cfg.offsets_mm();
  for (int n = 0; n < P; ++n) {
    Eigen::Vector4d r;
    for (int j = 0; j < 4; ++j)
      r(j) = m_um(n, j) - f(n + k[static_cast<std::size_t>(j)]) - e(j);
    const double S = parts.w_S.dot(r), g = parts.w_g.dot(r);  // g in µm/mm
    res.S_um(n) = S;
    res.gamma_rad(n) = 1e-3 * g;
    for (int j = 0; j < 4; ++j)
      res.sensor_residual_um(n, j) = r(j) - S - O[static_cast<std::size_t>(j)] * g;
  }

  if (opts.compute_uncertainty) {
    // Per point from the selected inverse Z of the factor: u² = σ̂²(‖w‖² + tᵀZt) with t = h − a_h·g
    // the gauge-fixed coefficients of the quantity (at most 4 f-unknowns and η̃: inside the band).
    const SelectedInverse& z = solver->selected_inverse();
    Eigen::VectorXd g_red = Eigen::VectorXd::Zero(parts.n_all);
    for (int i = 0; i < N; ++i) {
      const int col = parts.f_index[static_cast<std::size_t>(i)];
      if (col >= 0) g_red(col) = parts.bow(i);
    }
    const Eigen::VectorXd Zg = solver->solve_normal(g_red);
    const double gZg = g_red.dot(Zg);
    // tᵀZt for t = h − a·g, h given by (unknown, coefficient) pairs.
    auto quad = [&](const std::vector<std::pair<int, double>>& h, double nh) {
      const double ah = nh / parts.gn;
      double hZh = 0.0, hZg = 0.0;
      for (const auto& [i, ci] : h) {
        hZg += ci * Zg(i);
        for (const auto& [j, cj] : h)
          hZh += ci * cj * z(i, j);
      }
      return hZh - 2.0 * ah * hZg + ah * ah * gZg;
    };
    res.u_S_um.resize(P);
    res.u_gamma_rad.resize(P);
    res.u_f_um = Eigen::VectorXd::Zero(N);
    std::vector<std::pair<int, double>> h;
    // S and γ at a position take the same unknowns (its f̃ samples and η̃) with other weights:
    // the block of Z over them is read once for both (summed in the same order as quad()).
    const Eigen::Vector2d ew_S = parts.E.transpose() * parts.w_S,
                          ew_g = parts.E.transpose() * parts.w_g;
    for (int n = 0; n < P; ++n) {
      std::array<int, 6> cols{};
      int nc = 0;
      for (int j = 0; j < 4; ++j) {
        const int col = parts.f_index[static_cast<std::size_t>(n + k[static_cast<std::size_t>(j)])];
        if (col >= 0) cols[static_cast<std::size_t>(nc++)] = col;
      }
      cols[static_cast<std::size_t>(nc++)] = parts.m;
      cols[static_cast<std::size_t>(nc++)] = parts.m + 1;
      double zb[6][6];
      for (int p = 0; p < nc; ++p)
        for (int c = 0; c < nc; ++c)
          zb[p][c] = z(cols[static_cast<std::size_t>(p)], cols[static_cast<std::size_t>(c)]);
      for (int which = 0; which < 2; ++which) {
        const Eigen::Vector4d& w = which == 0 ? parts.w_S : parts.w_g;
        const Eigen::Vector2d& ew = which == 0 ? ew_S : ew_g;
        std::array<double, 6> coef{};
        int q = 0;
        double nh = 0.0;
        for (int j = 0; j < 4; ++j) {
          const int i = n + k[static_cast<std::size_t>(j)];
          if (parts.f_index[static_cast<std::size_t>(i)] >= 0)
            coef[static_cast<std::size_t>(q++)] = w(j);
          nh += w(j) * parts.bow(i);
        }
        coef[static_cast<std::size_t>(q++)] = ew(0);
        coef[static_cast<std::size_t>(q++)] = ew(1);
        nh += ew.dot(parts.n_eta);
        // quad() on the block: tᵀZt for t = h − a_h·g.
        const double ah = nh / parts.gn;
        double hZh = 0.0, hZg = 0.0;
        for (int p = 0; p < nc; ++p) {
          const double cp = coef[static_cast<std::size_t>(p)];
          hZg += cp * Zg(cols[static_cast<std::size_t>(p)]);
          for (int c = 0; c < nc; ++c)
            hZh += cp * coef[static_cast<std::size_t>(c)] * zb[p][c];
        }
        const double qf = hZh - 2.0 * ah * hZg + ah * ah * gZg;
        const double u = std::sqrt(std::max(0.0, sigma2 * (w.squaredNorm() + qf)));
        if (which == 0)
          res.u_S_um(n) = u;
        else
          res.u_gamma_rad(n) = 1e-3 * u;
      }
    }
    for (int i = 1; i < N - 1; ++i) {
      const int col = parts.f_index[static_cast<std::size_t>(i)];
      h.clear();
      if (col >= 0) h.emplace_back(col, 1.0);
      res.u_f_um(i) = std::sqrt(std::max(0.0, sigma2 * quad(h, parts.bow(i))));
    }
    res.solver_stats = solver->stats();
    parts.solver = std::move(solver);
    res.covariance = std::make_shared<FourSensorCovariance>(
        std::make_unique<FourSensorCovariance::Parts>(std::move(parts)));
  } else {
    res.solver_stats = solver->stats();
  }
  res.solver_stats.factorizations += extra_factorizations;

  // What the data could not determine.
  char note[512];
  std::snprintf(note, sizeof note,
                "one scan cannot see the constant, line and bow of f: f(x_0) = f(x_end) = 0 and "
                "f has no bow (the reference is taken as free of curvature), so the bow of S is "
                "measured relative to the reference's");
  res.determination_note = note;
  if (res.lambda_fallback == LambdaFallback::collapse_least_squares) {
    const double umax = res.u_S_um.size() ? res.u_S_um.maxCoeff() : 0.0;
    std::snprintf(note, sizeof note,
                  "; the %s prior left f with %.2g effective degrees of freedom (lambda %.3g): "
                  "not used, the unregularised separation is reported, and S is undetermined at "
                  "the level of u_S up to %.3g um",
                  to_string(opts.penalty), res.edf_f, rejected_lambda, umax);
    res.determination_note += note;
  }
  if (!res.lambda_rejected.empty()) {
    // The search went on without these λ; say so, with the first reason (issue 15).
    std::snprintf(note, sizeof note,
                  "; %zu lambda value(s) of the search rejected because the factor of "
                  "A'A + lambda^2 P lost precision (first: ",
                  res.lambda_rejected.size());
    res.determination_note += note + res.lambda_rejected.front() + ")";
  }
  res.lambda_at_refused_edge = refused_edge;
  if (refused_edge) {
    // Not bracketed (issue 15): the λ beyond the rule's best were refused, so the criterion's
    // minimum may lie there; lambda_at_edge is set.
    std::snprintf(note, sizeof note,
                  "; the %s minimum is not bracketed: the criterion still falls at the last "
                  "lambda of the search's grid that the factorisation accepted and the lambda "
                  "beyond it were refused, so the search's lambda %.3g may not be the minimum "
                  "(lambda at the edge)",
                  to_string(opts.rule), rule_lambda);
    res.determination_note += note;
  }
  res.total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

FourSensorPrediction predict_four_sensor_uncertainty(const FourSensorConfig& cfg, double sigma_um) {
  if (!(std::isfinite(sigma_um) && sigma_um > 0.0))
    throw std::invalid_argument("predict_four_sensor_uncertainty: sigma_um = " +
                                std::to_string(sigma_um) + ": must be a positive finite noise");
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  FourSensorOptions o;
  o.penalty = Penalty::none;
  o.rule = LambdaRule::least_squares;
  // Zero readings: the estimate is zero, and the covariance is what any readings would give.
  FourSensorResult r =
      separate_posterior(cfg, Eigen::MatrixXd::Zero(cfg.positions(), 4), o, sigma_um);
  FourSensorPrediction out;
  out.config = cfg;
  out.sigma_um = sigma_um;
  out.x_mm = std::move(r.x_mm);
  out.u_S_um = std::move(r.u_S_um);
  out.u_gamma_rad = std::move(r.u_gamma_rad);
  out.u_f_um = std::move(r.u_f_um);
  out.covariance = std::move(r.covariance);
  return out;
}

}  // namespace errsep::core
