#pragma once
// The four-sensor method (Zhao et al. 2019) read as a Bayesian linear model, so that the stated
// uncertainty of f, S and γ covers the truth.
//
// Data.  Each slide position n gives four readings m_j(x_n) = f(x_n + O_j) + S(x_n) + O_j·γ(x_n)
// + e_j + ε (Eq. 1), with independent noise ε of variance σ² on every reading (section 3: the
// noise is "added in m_i(x_n)").  Two combinations of the four readings cancel S and γ (the idea
// of Eq. 2): Qᵀm(x_n) with Q (4 × 2) orthonormal and orthogonal to 1 and to the offsets O.
// Because Q is orthonormal these two rows carry independent noise of the same σ²: the
// whitened form of Eq. (5), whose rows C·m are correlated (covariance σ²·C·Cᵀ).
//
// Unknowns x = [f(x_1) … f(x_{N−2}), η_1, η_2]: f(x_0) = f(x_{N−1}) = 0 are fixed exactly (the
// reference straight line of Eq. 11: columns removed, not rows added), and η = Qᵀe is the part of
// the zero-adjustment values that the data see.  The data cannot see the bow of f (a quadratic f
// changes Qᵀm by a constant per position, which η absorbs): the gauge "f has no bow"
// (CurvatureGauge::reference_without_curvature) fixes it after the solve, exactly.
//
// Prior.  f ~ N(0, σ²/λ²·(LᵀL)⁻¹), η flat: general-form Tikhonov with a smoothness operator L
// (Penalty).  The posterior mean solves (AᵀA + λ²LᵀL)x = Aᵀb, and the posterior covariance
// σ²(AᵀA + λ²LᵀL)⁻¹ contains the bias that the prior brings, which the covariance of the
// regularised estimate alone (what errsep reported before) does not: on long scans that one
// understated the error 30–70 times.  λ is chosen from the data by REML (the marginal likelihood
// of the data with σ held at the σ̂ of the redundant equations), GCV or the L-curve.
//
// The bow direction is null for AᵀA, so a third sample f(x_c) is pinned for the computation and
// the gauge moves it back; a prior acts on f itself through one more unknown that the data do
// not see (four_sensor_posterior.cpp).  Without a prior (Penalty::none) this is the exact
// covariance of the unbiased least-squares estimate.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"
#include "errsep/core/tikhonov_solver.hpp"

namespace errsep::core {

/// The prior on the reference profile f: the operator L of the penalty λ²‖L·f‖².
enum class Penalty {
  /// L = second differences of f: a smooth reference (an integrated random walk as a prior).
  /// Its spectrum rises as 1/ω⁴ toward long wavelengths, the slope of the four-sensor method's
  /// own noise transfer there, so the long wavelengths that the data barely see keep a large
  /// posterior uncertainty instead of being shrunk to nothing.  The default.
  second_difference,
  /// L = I: the paper's Eq. (17) applied to f.  Shrinks every weakly seen component of f toward
  /// zero; its uncertainty covers the truth only when f has no long-wavelength content.
  identity,
  /// No prior: the unregularised least-squares separation with its exact covariance.
  none,
};
const char* to_string(Penalty p);
/// "second_difference" | "identity" | "none" (the strings of to_string).
std::optional<Penalty> penalty_from_string(std::string_view s);

/// Q of the file comment: 4 × 2, orthonormal columns, Qᵀ·1 = 0 and Qᵀ·O = 0.
Eigen::Matrix<double, 4, 2> reading_combinations(const FourSensorConfig& cfg);

/// The system of the file comment.
struct PinnedSystem {
  /// 2P × (m + border): m band unknowns f̃ of f, then η̃_1, η̃_2, then (border 3) the bow
  /// amplitude β of f = f̃ + β·bow, whose column is empty (the data do not see it).
  Eigen::SparseMatrix<double> A;
  Eigen::VectorXd b;       ///< Qᵀm(x_n), stacked
  int band_unknowns = 0;   ///< m = N − 3
  int border = 2;          ///< 2 (η̃), or 3 with β
  int pinned_middle = -1;  ///< c = (N − 1)/2: f̃(x_c) = 0
  /// f_index[i]: the unknown of f̃(x_i), or −1 where it is pinned (i = 0, c, N − 1).
  std::vector<int> f_index;
};

/// Assembles the system for outputs m (P × 4, µm); `with_bow_unknown` adds β (needed by a prior).
/// Throws std::invalid_argument for a bad shape or configuration.
PinnedSystem assemble_pinned_system(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                    bool with_bow_unknown);

/// L over all unknowns of `sys` (built with the bow unknown), for a penalty other than none: the
/// operator applied to f = f̃ + β·bow with f's ends at 0 (rows × unknowns).  P = LᵀL.
Eigen::SparseMatrix<double> penalty_operator(const FourSensorConfig& cfg, Penalty penalty,
                                             const PinnedSystem& sys);

/// Covariance of linear functionals of a separation's f, S and γ, from the factor of its normal
/// matrix (kept alive by this object): what an ISO 230-1 figure whose value depends on a few
/// points needs (u_c² = cᵀVc), at the cost of one solve, without the dense P × P covariance.
/// Not thread-safe: one caller at a time.
class FourSensorCovariance {
 public:
  struct Parts;  // defined in four_sensor_posterior.cpp
  explicit FourSensorCovariance(std::unique_ptr<Parts> parts);
  ~FourSensorCovariance();
  FourSensorCovariance(const FourSensorCovariance&) = delete;
  FourSensorCovariance& operator=(const FourSensorCovariance&) = delete;

  /// Var(Σ_n a_n·S(x_n) + Σ_n b_n·γ(x_n) + Σ_i c_i·f(x_i)) with S in µm, γ in rad, f in µm.
  /// a and b have P entries, c has N; an empty vector stands for zeros.  Throws
  /// std::invalid_argument for a wrong size.
  double variance(const Eigen::VectorXd& a_S, const Eigen::VectorXd& b_gamma,
                  const Eigen::VectorXd& c_f);
  /// The covariance matrix of S at the given positions (indices 0..P−1), one solve per index.
  Eigen::MatrixXd covariance_S(const std::vector<int>& positions);
  /// Cov(S(x_n), Σ_m a(m, j)·S(x_m)) for every position n and each column j of `a_S` (P × q):
  /// the covariance of the whole profile with q linear functionals of it (e.g. the two of a
  /// least-squares line), one solve per column, O(P) more per column.  Throws
  /// std::invalid_argument for a wrong number of rows.
  Eigen::MatrixXd covariance_S_with(const Eigen::MatrixXd& a_S);
  /// One draw from the posterior (or, without a prior, the sampling distribution) of S and γ,
  /// as deviations from the estimate: dS (µm) and dγ (rad), P entries each.  One solve per draw:
  /// x_s − x̂ = M⁻¹(Aᵀσε₁ + λσLᵀε₂) has covariance σ²M⁻¹ (perturbation sampling), plus the
  /// readings' own noise in span{1, O} that S and γ take directly.
  void sample(std::uint64_t seed, Eigen::VectorXd& dS_um, Eigen::VectorXd& dgamma_rad);
  /// Adds G·K·Gᵀ to the covariance of (S, γ, f), G = [G_S; G_γ; G_f] (P × k in µm, P × k in rad,
  /// N × k in µm per unit of k parameters), K (k × k) symmetric positive semi-definite: what a
  /// refinement's fitted effect parameters carry into the separation of the corrected readings
  /// (refine.hpp).  Every later variance, covariance_S and sample includes it.  Throws
  /// std::invalid_argument for inconsistent sizes.
  void add_low_rank(const Eigen::MatrixXd& G_S, const Eigen::MatrixXd& G_gamma,
                    const Eigen::MatrixXd& G_f, const Eigen::MatrixXd& K);

 private:
  std::unique_ptr<Parts> p_;
};

/// The uncertainty of a separation before measuring (issue 15: the scan plan).  Without a prior
/// the separation is linear in the readings and its covariance σ²·(AᵀA)⁻¹ (plus the readings'
/// own noise in S and γ) depends on the geometry and σ only, not on the data: this is the exact
/// covariance of the unregularised separation (Penalty::none, LambdaRule::least_squares) that a
/// scan with this configuration will state, with σ given instead of estimated.  The default
/// estimator's posterior can only be tighter (a prior adds information), so this is what a scan
/// reaches without relying on the reference being smooth.
struct FourSensorPrediction {
  FourSensorConfig config;
  double sigma_um = 0.0;  ///< standard deviation of one reading as it enters (σ/√K for K averages)
  Eigen::VectorXd x_mm;                 ///< P slide positions
  Eigen::VectorXd u_S_um, u_gamma_rad;  ///< standard uncertainties (k = 1) at each position
  Eigen::VectorXd u_f_um;               ///< of the reference f at its N samples
  /// Covariances of linear functionals (straightness figures), from the kept factor.
  std::shared_ptr<FourSensorCovariance> covariance;
};

/// The prediction above for readings of standard deviation `sigma_um` (> 0).  Throws
/// std::invalid_argument for an invalid configuration, one without redundant readings
/// (2P < N), or a bad σ.
FourSensorPrediction predict_four_sensor_uncertainty(const FourSensorConfig& cfg, double sigma_um);

}  // namespace errsep::core
