#include "errsep/core/four_sensor_system.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace errsep::core {

const char* to_string(CurvatureGauge g) {
  switch (g) {
    case CurvatureGauge::reference_without_curvature:
      return "reference";
    case CurvatureGauge::sensor_stage_without_curvature:
      return "sensor_stage";
    case CurvatureGauge::paper_eq12_literal:
      return "paper_eq12";
  }
  return "unknown";
}

namespace {
constexpr CurvatureGauge kGauges[] = {CurvatureGauge::reference_without_curvature,
                                      CurvatureGauge::sensor_stage_without_curvature,
                                      CurvatureGauge::paper_eq12_literal};
}

std::optional<CurvatureGauge> curvature_gauge_from_string(std::string_view s) {
  for (auto g : kGauges)
    if (s == to_string(g)) return g;
  return std::nullopt;
}

std::vector<std::string> curvature_gauge_names() {
  std::vector<std::string> out;
  for (auto g : kGauges)
    out.emplace_back(to_string(g));
  return out;
}

Eigen::Matrix4d combination_matrix(const FourSensorConfig& cfg) {
  // Eq. (3).  Spacings enter only through their ratios, so integer s_i serve as well as D_i.
  const double D2 = cfg.s2, D3 = cfg.s3, D4 = cfg.s4;
  Eigen::Matrix4d C;
  C << 1, -(D2 + D3) / D3, D2 / D3, 0,                    //
      1, -(D2 + D3 + D4) / (D3 + D4), 0, D2 / (D3 + D4),  //
      1, 0, -(D2 + D3 + D4) / D4, (D2 + D3) / D4,         //
      0, 1, -(D3 + D4) / D4, D3 / D4;
  return C;
}

Eigen::Matrix<double, 2, 4> zero_adjustment_relations(const FourSensorConfig& cfg) {
  // Δe = C·e with rank(C) = 2, so Δe_3 and Δe_4 are fixed combinations of Δe_1 and Δe_2: find y
  // with yᵀC = 0 and y_3 = 1, y_4 = 0 (first relation) or y_3 = 0, y_4 = 1 (second).  This is
  // Eq. (13) derived from C rather than typed in; tests compare it with the printed formula.
  const Eigen::Matrix4d C = combination_matrix(cfg);
  Eigen::Matrix<double, 4, 2> M;  // columns: rows 1 and 2 of C, transposed
  M.col(0) = C.row(0).transpose();
  M.col(1) = C.row(1).transpose();
  Eigen::Matrix<double, 2, 4> Y;
  for (int k = 0; k < 2; ++k) {
    const Eigen::Vector4d target = -C.row(2 + k).transpose();
    const Eigen::Vector2d ab = M.colPivHouseholderQr().solve(target);
    Y.row(k) << ab(0), ab(1), k == 0 ? 1.0 : 0.0, k == 1 ? 1.0 : 0.0;
  }
  return Y;
}

Eigen::MatrixXd null_space_basis(const FourSensorConfig& cfg) {
  const int N = cfg.N;
  const double scale = 1.0 / (N - 1);
  Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(N + 4, 3);
  for (int n = 0; n < N; ++n) {
    const double t = n * scale;
    Z(n, 0) = 1.0;
    Z(n, 1) = t;
    Z(n, 2) = t * t;
  }
  const auto k = cfg.offsets_samples();
  Eigen::Vector4d k2;
  for (int j = 0; j < 4; ++j)
    k2(j) = (k[j] * scale) * (k[j] * scale);
  Z.block<4, 1>(N, 2) = -combination_matrix(cfg) * k2;
  return Z;
}

Eigen::Vector4d stage_curvature_direction(const FourSensorConfig& cfg) {
  const auto k = cfg.offsets_samples();
  const double scale = 1.0 / (k[3]);
  Eigen::Vector4d o2, o3;
  for (int j = 0; j < 4; ++j) {
    const double o = k[j] * scale;
    o2(j) = o * o;
    o3(j) = o * o * o;
  }
  const Eigen::Matrix4d C = combination_matrix(cfg);
  const Eigen::Vector4d q2 = C * o2, q3 = C * o3;
  return (q2 - (q2.dot(q3) / q3.squaredNorm()) * q3).normalized();
}

int system_rows(const FourSensorConfig& cfg, CurvatureGauge gauge, RowWeighting weighting) {
  const int per = weighting == RowWeighting::paper ? 4 : 2;
  return per * cfg.positions() + (gauge == CurvatureGauge::reference_without_curvature ? 2 : 5);
}

Eigen::VectorXd data_vector(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um) {
  const int P = cfg.positions();
  if (m_um.rows() != P || m_um.cols() != 4)
    throw std::invalid_argument("sensor outputs are " + std::to_string(m_um.rows()) + "x" +
                                std::to_string(m_um.cols()) + ", configuration needs " +
                                std::to_string(P) + "x4 (P = N - s2 - s3 - s4 slide positions)");
  const Eigen::Matrix4d C = combination_matrix(cfg);
  Eigen::VectorXd b0(4 * P);
  for (int n = 0; n < P; ++n)
    b0.segment<4>(4 * n) = C * m_um.row(n).transpose();  // Eq. (9)
  return b0;
}

Eigen::Matrix<double, 2, 4> whitening_matrix(const FourSensorConfig& cfg) {
  Eigen::JacobiSVD<Eigen::Matrix4d> svd(combination_matrix(cfg), Eigen::ComputeFullU);
  Eigen::Matrix<double, 2, 4> T;
  for (int r = 0; r < 2; ++r)
    T.row(r) = svd.matrixU().col(r).transpose() / svd.singularValues()(r);
  return T;
}

namespace {
// b of Eq. (16) from b₀ (4P, Eq. 6).
Eigen::VectorXd rhs_from_b0(const FourSensorConfig& cfg, const Eigen::VectorXd& b0,
                            CurvatureGauge gauge, RowWeighting weighting) {
  const int N = cfg.N, P = cfg.positions();
  const int per = weighting == RowWeighting::paper ? 4 : 2;
  Eigen::VectorXd b = Eigen::VectorXd::Zero(system_rows(cfg, gauge, weighting));
  if (weighting == RowWeighting::paper) {
    b.head(4 * P) = b0;
  } else {
    const Eigen::Matrix<double, 2, 4> T = whitening_matrix(cfg);
    for (int n = 0; n < P; ++n)
      b.segment<2>(2 * n) = T * b0.segment<4>(4 * n);
  }
  if (gauge == CurvatureGauge::paper_eq12_literal) {
    // Eq. (12) with f(x_{N−1}) = 0: Δe_1 = 2/(N(N−1)) Σ_{i=1}^{N−1} (N−i) g_1(x_{i−1}); only the
    // g_1 that exist (i − 1 <= p) can be summed.
    double sum = 0.0;
    for (int i = 1; i <= N - 1 && i - 1 < P; ++i)
      sum += (N - i) * b0(4 * (i - 1));
    b(per * P + 2) = 2.0 / (static_cast<double>(N) * (N - 1)) * sum;
  }
  return b;
}
}  // namespace

Eigen::VectorXd right_hand_side(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                CurvatureGauge gauge, RowWeighting weighting) {
  return rhs_from_b0(cfg, data_vector(cfg, m_um), gauge, weighting);
}

Eigen::VectorXd right_hand_side_combined(const FourSensorConfig& cfg, const Eigen::MatrixXd& g_um,
                                         CurvatureGauge gauge, RowWeighting weighting) {
  const int P = cfg.positions();
  if (g_um.rows() != P || g_um.cols() != 4)
    throw std::invalid_argument("combined outputs are " + std::to_string(g_um.rows()) + "x" +
                                std::to_string(g_um.cols()) + ", configuration needs " +
                                std::to_string(P) + "x4");
  Eigen::VectorXd b0(4 * P);
  for (int n = 0; n < P; ++n)
    b0.segment<4>(4 * n) = g_um.row(n).transpose();
  return rhs_from_b0(cfg, b0, gauge, weighting);
}

AugmentedSystem assemble_four_sensor_system(const FourSensorConfig& cfg,
                                            const Eigen::MatrixXd& m_um, CurvatureGauge gauge,
                                            RowWeighting weighting) {
  std::string why;
  if (!cfg.is_valid(&why)) throw std::invalid_argument("invalid configuration: " + why);
  const int N = cfg.N, P = cfg.positions();
  const Eigen::Matrix4d C = combination_matrix(cfg);
  const auto k = cfg.offsets_samples();

  AugmentedSystem sys;
  sys.gauge = gauge;
  sys.weighting = weighting;
  const int per = weighting == RowWeighting::paper ? 4 : 2;
  sys.data_rows = per * P;
  const int rows = system_rows(cfg, gauge, weighting), cols = N + 4;
  // The rows of one slide position: R·C on the f columns and R on the Δe columns, R = I (paper)
  // or the whitening T.
  Eigen::MatrixXd R = Eigen::MatrixXd::Identity(4, 4);
  if (weighting == RowWeighting::whitened) R = whitening_matrix(cfg);
  const Eigen::MatrixXd RC = R * C;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(static_cast<std::size_t>(4 * P) * 5 + 16);

  // Eqs. (5), (8): block row n places C on the columns of f(x_n + O_j), j = 1..4 — for general
  // spacings those are n, n+s2, n+s2+s3, n+s2+s3+s4 (Eq. 8 as printed shows the contiguous case
  // s2 = s3 = s4 = 1) — and the identity on the Δe columns.
  for (int n = 0; n < P; ++n) {
    for (int r = 0; r < per; ++r) {
      const int row = per * n + r;
      for (int j = 0; j < 4; ++j)
        if (std::abs(RC(r, j)) > 1e-14) trip.emplace_back(row, n + k[j], RC(r, j));
      for (int j = 0; j < 4; ++j)
        if (std::abs(R(r, j)) > 1e-14) trip.emplace_back(row, N + j, R(r, j));
    }
  }
  sys.b = right_hand_side(cfg, m_um, gauge, weighting);

  int row = per * P;
  if (gauge != CurvatureGauge::reference_without_curvature) {
    trip.emplace_back(row++, 0, 1.0);      // Eq. (11): f(x_0) = 0
    trip.emplace_back(row++, N - 1, 1.0);  // Eq. (11): f(x_{N-1}) = 0
    if (gauge == CurvatureGauge::paper_eq12_literal) {
      trip.emplace_back(row++, N + 0, 1.0);  // Eq. (12): Δe_1 = (value in b, see right_hand_side)
    } else {
      const Eigen::Vector4d w = stage_curvature_direction(cfg);  // w·Δe = 0
      for (int r = 0; r < 4; ++r)
        if (std::abs(w(r)) > 1e-14) trip.emplace_back(row, N + r, w(r));
      ++row;
    }
  }

  // Eq. (13): Δe ∈ range(C).
  const Eigen::Matrix<double, 2, 4> Y = zero_adjustment_relations(cfg);
  for (int k2 = 0; k2 < 2; ++k2, ++row)
    for (int r = 0; r < 4; ++r)
      if (Y(k2, r) != 0.0) trip.emplace_back(row, N + r, Y(k2, r));

  sys.A.resize(rows, cols);
  sys.A.setFromTriplets(trip.begin(), trip.end());
  sys.A.makeCompressed();
  return sys;
}

void apply_gauge(const FourSensorConfig& cfg, CurvatureGauge gauge, Eigen::VectorXd& X) {
  if (gauge != CurvatureGauge::reference_without_curvature) return;
  const int N = cfg.N;
  const Eigen::VectorXd bow = reference_bow(cfg);
  const Eigen::MatrixXd Z = null_space_basis(cfg);
  // Conditions on X + Z·a: f(x_0) = 0, f(x_{N−1}) = 0 (Eq. 11), bow·f = 0.
  Eigen::Matrix3d G;
  Eigen::Vector3d h;
  G.row(0) = Z.row(0);
  G.row(1) = Z.row(N - 1);
  G.row(2) = bow.transpose() * Z.topRows(N);
  h << -X(0), -X(N - 1), -bow.dot(X.head(N));
  X += Z * G.partialPivLu().solve(h);
}

Eigen::VectorXd reference_bow(const FourSensorConfig& cfg) {
  const int N = cfg.N;
  Eigen::VectorXd bow(N);
  for (int n = 0; n < N; ++n) {
    const double t = static_cast<double>(n) / (N - 1);
    bow(n) = t * (1.0 - t);
  }
  return bow;
}
}  // namespace errsep::core
