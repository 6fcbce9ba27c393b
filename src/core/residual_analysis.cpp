#include "errsep/core/residual_analysis.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <stdexcept>
#include <unsupported/Eigen/FFT>
#include <vector>

namespace errsep::core {

Eigen::Matrix<double, 4, 2> residual_basis(const FourSensorConfig& cfg) {
  const auto O = cfg.offsets_mm();
  Eigen::Matrix<double, 4, 2> A;
  for (int i = 0; i < 4; ++i)
    A(i, 0) = 1.0, A(i, 1) = O[static_cast<std::size_t>(i)];
  Eigen::HouseholderQR<Eigen::Matrix<double, 4, 2>> qr(A);
  const Eigen::Matrix4d Q = qr.householderQ();
  return Q.rightCols<2>();
}

Eigen::VectorXd reduce_readings(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um) {
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("readings must be P x 4 = " + std::to_string(P) + " x 4, got " +
                                std::to_string(m_um.rows()) + " x " + std::to_string(m_um.cols()));
  const auto V = residual_basis(cfg);
  Eigen::VectorXd y(2 * P);
  for (int n = 0; n < P; ++n)
    y.segment<2>(2 * n) = V.transpose() * m_um.row(n).transpose();
  return y;
}

Eigen::MatrixXd reduce_columns(const FourSensorConfig& cfg, const Eigen::MatrixXd& J) {
  const int P = cfg.positions();
  if (J.rows() != 4 * P)
    throw std::invalid_argument("effect columns must have 4P = " + std::to_string(4 * P) +
                                " rows, got " + std::to_string(J.rows()));
  const auto V = residual_basis(cfg);
  Eigen::MatrixXd out(2 * P, J.cols());
  for (int n = 0; n < P; ++n)
    out.middleRows<2>(2 * n) = V.transpose() * J.middleRows<4>(4 * n);
  return out;
}

Eigen::MatrixXd expand_residual(const FourSensorConfig& cfg, const Eigen::VectorXd& r) {
  const int P = cfg.positions();
  if (r.size() != 2 * P) throw std::invalid_argument("reduced residual must have 2P entries");
  const auto V = residual_basis(cfg);
  Eigen::MatrixXd out(P, 4);
  for (int n = 0; n < P; ++n)
    out.row(n) = (V * r.segment<2>(2 * n)).transpose();
  return out;
}

Eigen::VectorXd stack_readings(const Eigen::MatrixXd& m_um) {
  Eigen::VectorXd v(m_um.size());
  for (Eigen::Index n = 0; n < m_um.rows(); ++n)
    for (Eigen::Index i = 0; i < m_um.cols(); ++i)
      v(n * m_um.cols() + i) = m_um(n, i);
  return v;
}

ResidualSpace::ResidualSpace(const FourSensorConfig& cfg) : cfg_(cfg) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  const int N = cfg.N, P = cfg.positions();
  const auto k = cfg.offsets_samples();
  const auto V = residual_basis(cfg);
  // Columns: f(x_0..x_{N-1}) then e_1..e_4; reading (n, i) sees f(x_{n+k_i}) + e_i.
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(2 * P, N + 4);
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i) {
      G.block<2, 1>(2 * n, n + k[static_cast<std::size_t>(i)]) += V.row(i).transpose();
      G.block<2, 1>(2 * n, N + i) += V.row(i).transpose();
    }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(G);
  qr.setThreshold(1e-10);
  const int r = static_cast<int>(qr.rank());
  Q_ = qr.householderQ() * Eigen::MatrixXd::Identity(2 * P, r);
}

int ResidualSpace::add(const Eigen::MatrixXd& J, double rel_tol) {
  if (J.rows() != rows()) throw std::invalid_argument("columns to add have the wrong row count");
  if (J.cols() == 0) return 0;
  Eigen::MatrixXd R = project_out(J);
  for (Eigen::Index c = 0; c < R.cols(); ++c) {
    const double nrm = J.col(c).norm();
    if (nrm > 0) R.col(c) /= nrm;
  }
  Eigen::BDCSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeThinU);
  int added = 0;
  for (Eigen::Index c = 0; c < svd.singularValues().size(); ++c)
    if (svd.singularValues()(c) > rel_tol) ++added;
  if (added == 0) return 0;
  Eigen::MatrixXd Qn(rows(), rank() + added);
  Qn << Q_, svd.matrixU().leftCols(added);
  Q_ = std::move(Qn);
  return added;
}

Eigen::VectorXd ResidualSpace::project_out(const Eigen::VectorXd& y) const {
  return y - Q_ * (Q_.transpose() * y);
}

Eigen::MatrixXd ResidualSpace::project_out(const Eigen::MatrixXd& Y) const {
  return Y - Q_ * (Q_.transpose() * Y);
}

Identifiability check_identifiability(const ResidualSpace& space, const Eigen::MatrixXd& J,
                                      double rel_tol) {
  Identifiability out;
  out.parameters = static_cast<int>(J.cols());
  if (J.cols() == 0) return out;
  Eigen::MatrixXd R = space.project_out(J);
  Eigen::VectorXd D(J.cols());
  for (Eigen::Index c = 0; c < J.cols(); ++c) {
    D(c) = J.col(c).norm();
    if (D(c) > 0) R.col(c) /= D(c);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeFullV);
  out.relative_sv = svd.singularValues();
  for (Eigen::Index c = 0; c < out.relative_sv.size(); ++c)
    if (out.relative_sv(c) > rel_tol) ++out.identifiable;
  const int k0 = out.parameters - out.identifiable;
  // Null directions in scaled coordinates are V's trailing columns; back in parameter units
  // p = D⁻¹·p̃, normalised.
  out.null_directions.resize(out.parameters, k0);
  for (int j = 0; j < k0; ++j) {
    Eigen::VectorXd v = svd.matrixV().col(out.identifiable + j);
    for (Eigen::Index c = 0; c < v.size(); ++c)
      v(c) = D(c) > 0 ? v(c) / D(c) : v(c);
    out.null_directions.col(j) = v.normalized();
  }
  return out;
}

bool ResidualAnalysisOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (lags < 1) return fail("lags = " + std::to_string(lags) + ": must be >= 1");
  if (mc_samples < 19)
    return fail("mc_samples = " + std::to_string(mc_samples) + ": must be >= 19");
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  // The smallest Monte-Carlo p-value is 1/(mc_samples + 1): below alpha only with enough draws.
  if (static_cast<double>(mc_samples + 1) * alpha <= 1.0)
    return fail("mc_samples = " + std::to_string(mc_samples) + " cannot reach alpha = " +
                std::to_string(alpha) + ": need mc_samples + 1 > 1/alpha");
  return true;
}

void whiteness_statistics(const Eigen::MatrixXd& r, int lags, double* ljung_box_q,
                          double* periodogram_ratio, Eigen::VectorXd* power) {
  const Eigen::Index P = r.rows();
  const int h = static_cast<int>(std::min<Eigen::Index>(lags, std::max<Eigen::Index>(1, P / 4)));
  double Q = 0;
  for (Eigen::Index i = 0; i < r.cols(); ++i) {
    const Eigen::VectorXd c = r.col(i).array() - r.col(i).mean();
    const double c0 = c.squaredNorm();
    if (c0 <= 0) continue;
    for (int k = 1; k <= h; ++k) {
      const double rho = c.head(P - k).dot(c.tail(P - k)) / c0;
      Q += static_cast<double>(P) * (P + 2) * rho * rho / static_cast<double>(P - k);
    }
  }
  *ljung_box_q = Q;
  const Eigen::Index K = P / 2;
  Eigen::VectorXd pw = Eigen::VectorXd::Zero(K);
  for (Eigen::Index k = 1; k <= K; ++k) {
    const double w = 2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(P);
    for (Eigen::Index i = 0; i < r.cols(); ++i) {
      double re = 0, im = 0;
      for (Eigen::Index n = 0; n < P; ++n) {
        re += r(n, i) * std::cos(w * static_cast<double>(n));
        im -= r(n, i) * std::sin(w * static_cast<double>(n));
      }
      pw(k - 1) += re * re + im * im;
    }
  }
  const double mean = K > 0 ? pw.mean() : 0.0;
  *periodogram_ratio = mean > 0 ? pw.maxCoeff() / mean : 0.0;
  if (power) *power = std::move(pw);
}

Eigen::MatrixXd scan_order_times_s(const FourSensorConfig& cfg, double speed_mm_per_s) {
  const int P = cfg.positions();
  const double T = P * cfg.dx_mm / speed_mm_per_s;
  Eigen::MatrixXd t(P, 4);
  for (int n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      t(n, i) = i * T + n * cfg.dx_mm / speed_mm_per_s;
  return t;
}

namespace {

// What the null distribution of the residual looks like position by position: the variance of
// ||r_n||² for unit noise (Σ over the two reduced rows of 1 − h_jj, h = leverage), and the time
// order of the 4P readings.
struct NullShape {
  Eigen::VectorXd energy_var;   // P
  std::vector<int> time_order;  // indices n·4 + i in time order
};

constexpr int kStatistics = 5;
constexpr const char* kStatisticNames[kStatistics] = {
    "Ljung-Box", "periodogram peak", "cumulative periodogram", "runs", "local excess"};

struct Statistics {
  double v[kStatistics] = {0, 0, 0, 0, 0};  // larger = less white
  Eigen::Index local_start = 0, local_width = 0;
};

Statistics all_statistics(const Eigen::MatrixXd& res, const Eigen::VectorXd& r_reduced, int lags,
                          const NullShape& ns, Eigen::VectorXd* power = nullptr) {
  Statistics st;
  const Eigen::Index P = res.rows();
  Eigen::VectorXd pw;
  whiteness_statistics(res, lags, &st.v[0], &st.v[1], &pw);
  // Bartlett: KS distance of the cumulative periodogram from the uniform line.
  const double total = pw.sum();
  if (total > 0 && pw.size() > 1) {
    double c = 0, d = 0;
    const auto K = static_cast<double>(pw.size());
    for (Eigen::Index k = 0; k < pw.size(); ++k) {
      c += pw(k) / total;
      d = std::max(d, std::abs(c - static_cast<double>(k + 1) / K));
    }
    st.v[2] = d;
  }
  // Runs of the signs in time order (zeros, which only an exact fit gives, count as +).
  {
    long n_pos = 0, n_neg = 0, runs = 0;
    int prev = 0;
    for (int a : ns.time_order) {
      const int sgn = res(a / 4, a % 4) >= 0 ? 1 : -1;
      (sgn > 0 ? n_pos : n_neg)++;
      if (sgn != prev) ++runs;
      prev = sgn;
    }
    const auto n = static_cast<double>(n_pos + n_neg);
    const double np = static_cast<double>(n_pos), nn = static_cast<double>(n_neg);
    const double expect = 1.0 + 2.0 * np * nn / n;
    const double var = 2.0 * np * nn * (2.0 * np * nn - n) / (n * n * (n - 1.0));
    st.v[3] = var > 0 ? (expect - static_cast<double>(runs)) / std::sqrt(var) : 0.0;
  }
  // Local excess: windows of w positions, energy over its null expectation σ̂²·Σ var, as a
  // Wilson–Hilferty z (a χ²_d/d-like ratio made comparable across widths).
  {
    const double dof = ns.energy_var.sum();
    const double s2 = dof > 0 ? r_reduced.squaredNorm() / dof : 0.0;
    double best = -std::numeric_limits<double>::infinity();
    if (s2 > 0) {
      Eigen::VectorXd e(P);
      for (Eigen::Index n = 0; n < P; ++n)
        e(n) = r_reduced.segment<2>(2 * n).squaredNorm();
      for (Eigen::Index w : {1, 2, 3, 5, 8}) {
        if (w > P) break;
        double se = e.head(w).sum(), sv = ns.energy_var.head(w).sum();
        for (Eigen::Index n0 = 0;; ++n0) {
          if (sv > 0.5) {  // windows at the ends where the model fits (almost) exactly carry
                           // no information
            const double x = se / (s2 * sv);
            const double a = 2.0 / (9.0 * sv);
            const double z = (std::cbrt(x) - (1.0 - a)) / std::sqrt(a);
            if (z > best) {
              best = z;
              st.local_start = n0;
              st.local_width = w;
            }
          }
          if (n0 + w >= P) break;
          se += e(n0 + w) - e(n0);
          sv += ns.energy_var(n0 + w) - ns.energy_var(n0);
        }
      }
    }
    st.v[4] = std::isfinite(best) ? best : 0.0;
  }
  if (power) *power = std::move(pw);
  return st;
}

// Upper-tail p-value of a statistic from Monte-Carlo draws: the empirical fraction where at least
// kTailCount draws are as large, an exponential tail fitted to the largest draws beyond that
// (peaks over threshold with the mean excess as scale).  Without the extrapolation every value
// beyond the largest draw would get the same p = 1/(M+1), and the minimum over five statistics
// could then not be told from the draws' own minima: the combined p-value would sit near
// 5/(M+1) however far out the data are.  The combination stays calibrated whatever this
// function is, because the data and the draws go through the same one.
class UpperTail {
 public:
  explicit UpperTail(std::vector<double> draws) : d_(std::move(draws)) {
    std::sort(d_.begin(), d_.end());
    const auto n = static_cast<std::ptrdiff_t>(d_.size());
    n_tail_ = std::max<std::ptrdiff_t>(std::min<std::ptrdiff_t>(kTailCount, n), n / 10);
    u_ = d_[static_cast<std::size_t>(n - n_tail_)];
    double excess = 0;
    for (std::ptrdiff_t i = n - n_tail_; i < n; ++i)
      excess += d_[static_cast<std::size_t>(i)] - u_;
    beta_ = excess / static_cast<double>(n_tail_);
  }
  double p_value(double t) const {
    const double M = static_cast<double>(d_.size()) + 1.0;
    const auto ge = d_.end() - std::lower_bound(d_.begin(), d_.end(), t);
    if (ge >= n_tail_ || !(beta_ > 0)) return (1.0 + static_cast<double>(ge)) / M;
    return (static_cast<double>(n_tail_) / M) * std::exp(-(t - u_) / beta_);
  }

 private:
  static constexpr std::ptrdiff_t kTailCount = 10;
  std::vector<double> d_;
  std::ptrdiff_t n_tail_ = 0;
  double u_ = 0, beta_ = 0;
};

// The p-values of a Monte-Carlo pool: row 0 the data's statistics, rows 1.. the draws'.  Each
// statistic's tail is fitted to the data and the draws together, so that every member of the pool,
// the data included, counts itself: the members are treated alike, exchangeable under the null, and
// the rank of the data's smallest p among the pool's smallest p is an exact level-α test.
void pool_p_values(const Eigen::MatrixXd& T, double alpha, WhitenessTest& w) {
  const auto M = static_cast<int>(T.rows());
  Eigen::MatrixXd p(M, kStatistics);
  for (int j = 0; j < kStatistics; ++j) {
    std::vector<double> draws(T.col(j).data(), T.col(j).data() + M);
    const UpperTail tail(std::move(draws));
    for (int s = 0; s < M; ++s)
      p(s, j) = tail.p_value(T(s, j));
  }
  const Eigen::VectorXd minp = p.rowwise().minCoeff();
  int le = 0;
  for (int s = 0; s < M; ++s)
    if (minp(s) <= minp(0)) ++le;
  w.p_ljung_box = p(0, 0);
  w.p_periodogram = p(0, 1);
  w.p_cumulative_periodogram = p(0, 2);
  w.p_runs = p(0, 3);
  w.p_local = p(0, 4);
  w.p_value = static_cast<double>(le) / M;
  if (w.p_value < alpha) {
    Eigen::Index jmin = 0;
    p.row(0).minCoeff(&jmin);
    for (int j = 0; j < kStatistics; ++j)
      if (j == jmin || p(0, j) < alpha) {
        if (!w.rejected_by.empty()) w.rejected_by += ", ";
        w.rejected_by += kStatisticNames[j];
      }
  }
}

}  // namespace

ResidualAnalysis analyse_residual(const ResidualSpace& space, const Eigen::MatrixXd& m_um,
                                  const Eigen::MatrixXd& t_s, const ResidualAnalysisOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid residual options: " + why);
  const FourSensorConfig& cfg = space.config();
  const int P = cfg.positions();
  const Eigen::MatrixXd t = t_s.size() == 0 ? scan_order_times_s(cfg) : t_s;
  if (t.rows() != P || t.cols() != 4)
    throw std::invalid_argument("reading times must be P x 4 like the readings");

  ResidualAnalysis out;
  const Eigen::VectorXd r = space.project_out(reduce_readings(cfg, m_um));
  out.residual_um = expand_residual(cfg, r);
  out.rss_um2 = r.squaredNorm();
  out.dof = space.dof();
  out.sigma_um = out.dof > 0 ? std::sqrt(out.rss_um2 / out.dof) : 0.0;
  out.rms_um = std::sqrt(out.rss_um2 / (4.0 * P));
  out.rms_per_config_um = (out.residual_um.colwise().squaredNorm() / P).array().sqrt().transpose();
  out.rms_per_position_um = (out.residual_um.rowwise().squaredNorm() / 4.0).array().sqrt();

  std::vector<int> idx(4 * static_cast<std::size_t>(P));
  std::iota(idx.begin(), idx.end(), 0);
  std::stable_sort(idx.begin(), idx.end(),
                   [&](int a, int b) { return t(a / 4, a % 4) < t(b / 4, b % 4); });
  out.time_s.resize(4 * P);
  out.residual_time_order_um.resize(4 * P);
  for (int j = 0; j < 4 * P; ++j) {
    const int a = idx[static_cast<std::size_t>(j)];
    out.time_s(j) = t(a / 4, a % 4);
    out.residual_time_order_um(j) = out.residual_um(a / 4, a % 4);
  }

  NullShape ns;
  ns.time_order = idx;
  {
    const Eigen::MatrixXd& Q = space.basis();
    ns.energy_var.resize(P);
    for (int n = 0; n < P; ++n)
      ns.energy_var(n) = 2.0 - Q.middleRows<2>(2 * n).squaredNorm();
  }
  WhitenessTest& w = out.whiteness;
  w.lags = std::min(opts.lags, std::max(1, P / 4));
  w.mc_samples = opts.mc_samples;
  const Statistics data = all_statistics(out.residual_um, r, w.lags, ns, &out.periodogram_power);
  w.ljung_box_q = data.v[0];
  w.periodogram_ratio = data.v[1];
  w.cumulative_periodogram_d = data.v[2];
  w.runs_z = data.v[3];
  w.local_z = data.v[4];
  w.local_x_mm =
      (static_cast<double>(data.local_start) + 0.5 * static_cast<double>(data.local_width - 1)) *
      cfg.dx_mm;
  w.local_width_mm = static_cast<double>(data.local_width) * cfg.dx_mm;
  const Eigen::Index K = out.periodogram_power.size();
  out.periodogram_period_mm.resize(K);
  for (Eigen::Index k = 1; k <= K; ++k)
    out.periodogram_period_mm(k - 1) = P * cfg.dx_mm / static_cast<double>(k);
  if (K > 0) {
    Eigen::Index kmax = 0;
    out.periodogram_power.maxCoeff(&kmax);
    out.dominant_period_mm = out.periodogram_period_mm(kmax);
  }
  if (out.dof > 0 && out.rss_um2 > 0) {
    // Pool the data (row 0) with the draws; each statistic's p-value is its upper rank in the
    // pool, and the p-value of the data's smallest p is the rank of that minimum among the
    // pool's minima (the draws and the data are exchangeable under the null).
    const int M = opts.mc_samples + 1;
    Eigen::MatrixXd T(M, kStatistics);
    for (int j = 0; j < kStatistics; ++j)
      T(0, j) = data.v[j];
    std::mt19937_64 rng(opts.seed);
    std::normal_distribution<double> g(0.0, 1.0);
    Eigen::VectorXd z(2 * P);
    for (int s = 1; s < M; ++s) {
      for (Eigen::Index j = 0; j < z.size(); ++j)
        z(j) = g(rng);
      const Eigen::VectorXd rz = space.project_out(z);
      const Statistics st = all_statistics(expand_residual(cfg, rz), rz, w.lags, ns);
      for (int j = 0; j < kStatistics; ++j)
        T(s, j) = st.v[j];
    }
    pool_p_values(T, opts.alpha, w);
  }
  w.white = w.p_value >= opts.alpha;
  return out;
}

}  // namespace errsep::core

namespace errsep::core {
namespace {

// The five statistics of a ProjectedResidual (larger = less white), each channel scaled by its
// own σ̂ first.  Same definitions as all_statistics above, along time instead of position.
Statistics projected_statistics(const Eigen::MatrixXd& raw, const Eigen::MatrixXd& pdiag, int lags,
                                Eigen::VectorXd* power = nullptr) {
  Statistics st;
  const Eigen::Index L = raw.rows(), C = raw.cols();
  Eigen::MatrixXd r = raw;
  for (Eigen::Index c = 0; c < C; ++c) {
    const double dof = pdiag.col(c).sum();
    const double s2 = dof > 0 ? r.col(c).squaredNorm() / dof : 0.0;
    if (s2 > 0) r.col(c) /= std::sqrt(s2);
  }
  // Ljung–Box per channel, summed.
  const int h = static_cast<int>(std::min<Eigen::Index>(lags, std::max<Eigen::Index>(1, L / 4)));
  for (Eigen::Index c = 0; c < C; ++c) {
    const Eigen::VectorXd v = r.col(c).array() - r.col(c).mean();
    const double c0 = v.squaredNorm();
    if (c0 <= 0) continue;
    for (int k = 1; k <= h && k < L; ++k) {
      const double rho = v.head(L - k).dot(v.tail(L - k)) / c0;
      st.v[0] += static_cast<double>(L) * static_cast<double>(L + 2) * rho * rho /
                 static_cast<double>(L - k);
    }
  }
  // Channel-summed periodogram (FFT: the series are as long as a grid has points).
  const Eigen::Index K = L / 2;
  Eigen::VectorXd pw = Eigen::VectorXd::Zero(K);
  {
    Eigen::FFT<double> fft;
    std::vector<double> in(static_cast<std::size_t>(L));
    std::vector<std::complex<double>> out;
    for (Eigen::Index c = 0; c < C; ++c) {
      for (Eigen::Index t = 0; t < L; ++t)
        in[static_cast<std::size_t>(t)] = r(t, c);
      fft.fwd(out, in);
      for (Eigen::Index k = 1; k <= K; ++k)
        pw(k - 1) += std::norm(out[static_cast<std::size_t>(k)]);
    }
  }
  const double mean = K > 0 ? pw.mean() : 0.0;
  st.v[1] = mean > 0 ? pw.maxCoeff() / mean : 0.0;
  const double total = pw.sum();
  if (total > 0 && K > 1) {
    double cum = 0, d = 0;
    for (Eigen::Index k = 0; k < K; ++k) {
      cum += pw(k) / total;
      d = std::max(d, std::abs(cum - static_cast<double>(k + 1) / static_cast<double>(K)));
    }
    st.v[2] = d;
  }
  // Runs of the signs in time order; an equation the model fits exactly (Π_tt = 0) carries no
  // sign and is skipped.
  {
    long n_pos = 0, n_neg = 0, runs = 0;
    int prev = 0;
    for (Eigen::Index t = 0; t < L; ++t)
      for (Eigen::Index c = 0; c < C; ++c) {
        if (pdiag(t, c) <= 1e-12) continue;
        const int sgn = r(t, c) >= 0 ? 1 : -1;
        (sgn > 0 ? n_pos : n_neg)++;
        if (sgn != prev) ++runs;
        prev = sgn;
      }
    const auto n = static_cast<double>(n_pos + n_neg);
    const double np = static_cast<double>(n_pos), nn = static_cast<double>(n_neg);
    if (n > 1) {
      const double expect = 1.0 + 2.0 * np * nn / n;
      const double var = 2.0 * np * nn * (2.0 * np * nn - n) / (n * n * (n - 1.0));
      st.v[3] = var > 0 ? (expect - static_cast<double>(runs)) / std::sqrt(var) : 0.0;
    }
  }
  // Local excess over windows of consecutive instants (Wilson–Hilferty z as in all_statistics).
  {
    const Eigen::VectorXd e = r.rowwise().squaredNorm();
    const Eigen::VectorXd ev = pdiag.rowwise().sum();
    const double dof = ev.sum();
    const double s2 = dof > 0 ? e.sum() / dof : 0.0;
    double best = -std::numeric_limits<double>::infinity();
    if (s2 > 0) {
      for (Eigen::Index w : {1, 2, 3, 5, 8}) {
        if (w > L) break;
        double se = e.head(w).sum(), sv = ev.head(w).sum();
        for (Eigen::Index n0 = 0;; ++n0) {
          const double x = se / (s2 * sv);
          const double a = 2.0 / (9.0 * sv);
          // z <= sqrt(a) for x <= 1: such a window cannot beat a best above that (saves most of
          // the cube roots, the bulk of the Monte-Carlo time).
          if (sv > 0.5 && !(x <= 1.0 && best >= std::sqrt(a))) {
            const double z = (std::cbrt(x) - (1.0 - a)) / std::sqrt(a);
            if (z > best) {
              best = z;
              st.local_start = n0;
              st.local_width = w;
            }
          }
          if (n0 + w >= L) break;
          se += e(n0 + w) - e(n0);
          sv += ev(n0 + w) - ev(n0);
        }
      }
    }
    st.v[4] = std::isfinite(best) ? best : 0.0;
  }
  if (power) *power = std::move(pw);
  return st;
}

}  // namespace

WhitenessTest test_projected_whiteness(const ProjectedResidual& pr,
                                       const ResidualAnalysisOptions& opts,
                                       Eigen::VectorXd* power) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid residual options: " + why);
  const Eigen::Index L = pr.residual.rows(), C = pr.residual.cols();
  if (pr.projector_diagonal.rows() != L || pr.projector_diagonal.cols() != C)
    throw std::invalid_argument(
        "projected residual: the projector diagonal must be L x C like "
        "the residual");
  if (!pr.project) throw std::invalid_argument("projected residual: no projector given");
  WhitenessTest w;
  w.lags = static_cast<int>(std::min<Eigen::Index>(opts.lags, std::max<Eigen::Index>(1, L / 4)));
  w.mc_samples = opts.mc_samples;
  const Statistics data = projected_statistics(pr.residual, pr.projector_diagonal, w.lags, power);
  w.ljung_box_q = data.v[0];
  w.periodogram_ratio = data.v[1];
  w.cumulative_periodogram_d = data.v[2];
  w.runs_z = data.v[3];
  w.local_z = data.v[4];
  w.local_x_mm =
      static_cast<double>(data.local_start) + 0.5 * static_cast<double>(data.local_width - 1);
  w.local_width_mm = static_cast<double>(data.local_width);
  const double dof = pr.projector_diagonal.sum();
  if (L < 2 || !(dof > 0.5) || !(pr.residual.squaredNorm() > 0)) {
    w.white = true;  // nothing to test: reported by the caller through its dof
    return w;
  }
  const int M = opts.mc_samples + 1;
  Eigen::MatrixXd T(M, kStatistics);
  for (int j = 0; j < kStatistics; ++j)
    T(0, j) = data.v[j];
  std::mt19937_64 rng(opts.seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd z(L, C);
  for (int s = 1; s < M; ++s) {
    for (Eigen::Index c = 0; c < C; ++c)
      for (Eigen::Index t = 0; t < L; ++t)
        z(t, c) = g(rng);
    const Eigen::MatrixXd rz = pr.project(z);
    if (rz.rows() != L || rz.cols() != C)
      throw std::invalid_argument("projected residual: the projector changed the shape");
    const Statistics st = projected_statistics(rz, pr.projector_diagonal, w.lags);
    for (int j = 0; j < kStatistics; ++j)
      T(s, j) = st.v[j];
  }
  pool_p_values(T, opts.alpha, w);
  w.white = w.p_value >= opts.alpha;
  return w;
}

}  // namespace errsep::core
