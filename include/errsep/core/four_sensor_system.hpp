#pragma once
// The augmented linear system of the four-sensor method (Zhao et al. 2019, Eqs. 3–16), assembled
// directly in sparse form.
//
// Unknowns X = [f(x_0) … f(x_{N−1}), Δe_1 … Δe_4]ᵀ (Eq. 7), µm.
// Rows:  4·P data rows  c_n X = g(x_n) = C·m(x_n)            (Eqs. 2, 4–6, 8, 9)
//        f(x_0) = 0, f(x_{N−1}) = 0                          (Eq. 11: the reference straight line)
//        one curvature-gauge row                             (Eq. 12, see CurvatureGauge)
//        2 rows Δe ∈ range(C)                                (Eq. 13)
//
// Identifiability.  Every row of C sums to zero and has zero first moment in the sensor offsets
// O_i, so C annihilates any f that is constant or linear in x; a quadratic f = c·x² gives
// C·f = c·C·O² (O² = squared offsets), the same at every position, which the Δe terms absorb.
// So (const, linear, quadratic) of f are not identifiable from the data: the quadratic of f
// together with e_i growing with the square of the sensor position leaves every sensor output
// unchanged.  The constant and linear parts are fixed by Eq. (11).  The quadratic part is what
// Eq. (12) tries to fix; see CurvatureGauge.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "errsep/core/four_sensor_config.hpp"

namespace errsep::core {

/// How the three non-identifiable components of f (constant, linear, quadratic) are fixed.
enum class CurvatureGauge {
  /// The paper's structure with Eq. (12) replaced by an assumption that holds for any
  /// spacing.  Rows of A (weight 1, as Eq. 15 has them): Eq. (11), and: the zero-adjustment values
  /// of the sensor stage have no component quadratic in the sensor position (e = a + b·O + d·O³
  /// when expanded in 1, O, O², O³; a quadratic e_i is exactly what trades with a bow of f).  As a
  /// row: w·Δe = 0 with w the part of C·O² orthogonal to C·O³ (Δe = C·e, C kills 1 and O).  Like
  /// Eq. (12) the row moves Δe only by ~2/(N−1)² of a bow's amplitude, so for λ > 0 the Tikhonov
  /// term (minimum ‖X‖) effectively chooses the curvature; at λ = 0 the row does.
  sensor_stage_without_curvature,
  /// The default.  The reference surface has no curvature of its own, fixed exactly: Eq. (11) —
  /// f(x_0) =
  /// f(x_{N−1}) = 0 — and f has no component along the bow b(x_n) = t_n(1 − t_n), t_n = n/(N−1),
  /// the shape the unidentifiable quadratic takes between the two fixed ends.  This is what
  /// Eq. (12) must have meant (it fixes the curvature, and nothing else), stated as an assumption
  /// on f instead of a closure over data that do not exist.  Implemented exactly, not as weighted
  /// rows: A holds the data rows and Eq. (13) only, so its null space is spanned by the three
  /// known directions of null_space_basis(); for λ > 0 the Tikhonov solution is orthogonal to them
  /// (the regulariser never shrinks a polynomial trend), and apply_gauge() adds the unique
  /// combination of them that satisfies the three conditions.  Both stay sparse, so AᵀA stays
  /// banded, and no λ is needed to tame the bow: the L-curve of this system has a corner only
  /// when the noise really dominates the unregularised solution.
  ///
  /// Why the bow and not the discrete Legendre P2 (the first version): P2 weighs the ends of f
  /// most, and the far end f(x_{p+1}) … f(x_{N−1}) is seen only by sensor 4 at the last slide
  /// positions, so a P2 condition imports that end's noise into the curvature of the whole
  /// profile.  In a numerical experiment on Example 1 (noise on the combined outputs, one batch
  /// of 20 runs, σ = 0.1 µm, outside this suite): ΔS_max 1.23 µm with P2, 0.85 µm with the bow.
  /// For the paper's test profiles (odd about the centre) both conditions hold exactly.
  reference_without_curvature,
  /// Eqs. (11)–(12) as printed, as rows of A (weight 1): Δe_1 = 2/(N(N−1)) Σ_{i=1}^{N−1} (N−i)·
  /// g_1(x_{i−1}).  The sum runs to g_1(x_{N−2}), but g_1 exists only for x_0 … x_p
  /// (p = N − s2 − s3 − s4 − 1); the missing terms are dropped.  Kept to show what the literal
  /// reading does: a large bow in the unregularised solution (it silently assumes a zero start
  /// slope of f, not a property of the data).  With λ > 0 the weak Δe_1 row (the bow moves Δe_1 by
  /// only 2/(N−1)² of its amplitude) lets the regulariser pick the curvature instead.
  paper_eq12_literal,
};

/// "reference" | "sensor_stage" | "paper_eq12": the names the apps and the machine config use.
const char* to_string(CurvatureGauge g);
std::optional<CurvatureGauge> curvature_gauge_from_string(std::string_view s);
/// Every gauge's to_string, for option lists and messages.
std::vector<std::string> curvature_gauge_names();

/// How the 4 data rows of each slide position are weighted.
enum class RowWeighting {
  /// Eq. (5) as printed: the four rows C·m(x_n), unweighted.  C has rank 2, so the rows are
  /// redundant and their noise correlated (covariance σ²·C·Cᵀ).
  paper,
  /// Generalised least squares: the two whitened rows T·C·m(x_n), T = Σ₂⁻¹U₂ᵀ from the SVD of
  /// C (T·C = V₂ᵀ, an orthonormal basis of the complement of span{1, O}).  Same solution set
  /// for exact data; the minimum-variance (BLUE) weighting of the rows for white sensor noise.
  whitened,
};

/// The 4×4 matrix C of Eq. (3) for the configuration's spacings.  Its rows combine the four
/// outputs so that S(x_n) and γ(x_n) cancel (row r: Σ_j C_rj = 0 and Σ_j C_rj·O_j = 0).
Eigen::Matrix4d combination_matrix(const FourSensorConfig& cfg);

/// The two relations Δe must satisfy because Δe = C·e and C has rank 2 (Eq. 13): rows y with
/// y·Δe = 0, scaled so that the coefficient of Δe_3 (first row) and Δe_4 (second row) is 1 as in
/// the paper.
Eigen::Matrix<double, 2, 4> zero_adjustment_relations(const FourSensorConfig& cfg);

/// The null space of the data rows and Eq. (13), (N + 4) × 3: a constant f, a linear f, and the
/// curvature direction z_f(x_n) = t_n², t_n = n/(N−1), with z_Δe = −C·(k_j/(N−1))² (a quadratic
/// f = c·x² changes every row of C·f by c·C·O², which Δe absorbs).
Eigen::MatrixXd null_space_basis(const FourSensorConfig& cfg);

struct AugmentedSystem {
  Eigen::SparseMatrix<double> A;  ///< rows × (N + 4), Eq. (15) (see CurvatureGauge for the rows)
  Eigen::VectorXd b;              ///< Eq. (16)
  int data_rows = 0;              ///< 4P (paper) or 2P (whitened)
  CurvatureGauge gauge = CurvatureGauge::sensor_stage_without_curvature;
  RowWeighting weighting = RowWeighting::paper;
};

/// The data part b₀ (Eq. 6) of b from sensor outputs m (P × 4, µm): g(x_n) = C·m(x_n).
Eigen::VectorXd data_vector(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um);

/// b of Eq. (16) for outputs m (P × 4): b₀, the zeros of Eq. (11), the gauge row's value, the
/// zeros of Eq. (13).  Linear in m.
Eigen::VectorXd right_hand_side(const FourSensorConfig& cfg, const Eigen::MatrixXd& m_um,
                                CurvatureGauge gauge, RowWeighting weighting = RowWeighting::paper);

/// b of Eq. (16) from combined outputs g (P × 4, row n = g(x_n) of Eq. 9) measured directly.
Eigen::VectorXd right_hand_side_combined(const FourSensorConfig& cfg, const Eigen::MatrixXd& g_um,
                                         CurvatureGauge gauge,
                                         RowWeighting weighting = RowWeighting::paper);

/// The 2×4 whitening T of RowWeighting::whitened (rows of T·C orthonormal).
Eigen::Matrix<double, 2, 4> whitening_matrix(const FourSensorConfig& cfg);

/// Assembles A (Eq. 15) and b (Eq. 16) for outputs m (P × 4).  Throws std::invalid_argument if
/// the shape of m does not match the configuration.
AugmentedSystem assemble_four_sensor_system(const FourSensorConfig& cfg,
                                            const Eigen::MatrixXd& m_um, CurvatureGauge gauge,
                                            RowWeighting weighting = RowWeighting::paper);

/// Applies the gauge after a solve: for reference_without_curvature adds the combination of
/// null_space_basis() that makes f(x_0) = f(x_{N−1}) = 0 and bow·f = 0 (reference_bow()); no-op
/// for the other gauges (their rows are in A).
void apply_gauge(const FourSensorConfig& cfg, CurvatureGauge gauge, Eigen::VectorXd& X);

/// The bow t_n(1 − t_n), t_n = n/(N − 1), N samples: the quadratic that vanishes at both ends.
Eigen::VectorXd reference_bow(const FourSensorConfig& cfg);

/// The unit vector w of CurvatureGauge::sensor_stage_without_curvature (w·Δe = 0).
Eigen::Vector4d stage_curvature_direction(const FourSensorConfig& cfg);

/// Number of rows of A for a gauge and weighting.
int system_rows(const FourSensorConfig& cfg, CurvatureGauge gauge, RowWeighting weighting);

}  // namespace errsep::core
