#include "errsep/core/residual_analysis.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <random>
#include <stdexcept>
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

  WhitenessTest& w = out.whiteness;
  w.lags = std::min(opts.lags, std::max(1, P / 4));
  w.mc_samples = opts.mc_samples;
  whiteness_statistics(out.residual_um, w.lags, &w.ljung_box_q, &w.periodogram_ratio,
                       &out.periodogram_power);
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
    std::mt19937_64 rng(opts.seed);
    std::normal_distribution<double> g(0.0, 1.0);
    int ge_q = 0, ge_p = 0;
    Eigen::VectorXd z(2 * P);
    for (int s = 0; s < opts.mc_samples; ++s) {
      for (Eigen::Index j = 0; j < z.size(); ++j)
        z(j) = g(rng);
      const Eigen::MatrixXd rs = expand_residual(cfg, space.project_out(z));
      double q = 0, pr = 0;
      whiteness_statistics(rs, w.lags, &q, &pr);
      if (q >= w.ljung_box_q) ++ge_q;
      if (pr >= w.periodogram_ratio) ++ge_p;
    }
    w.p_ljung_box = (1.0 + ge_q) / (1.0 + opts.mc_samples);
    w.p_periodogram = (1.0 + ge_p) / (1.0 + opts.mc_samples);
    w.p_value = std::min(1.0, 2.0 * std::min(w.p_ljung_box, w.p_periodogram));
  }
  w.white = w.p_value >= opts.alpha;
  return out;
}

}  // namespace errsep::core
