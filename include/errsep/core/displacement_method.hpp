#pragma once
// One-axis displacement method (Haramiishi et al. 2024, section 2.1, Eqs. 1-9; after Thwaite
// 1973): sensor 1 reads the workpiece w(x), sensor 2 a reference piece r(x) built into the table;
// both see the table's motion error m(x):
//
//   S1_1(x) = w(x) + m(x)            (1)   first scan, workpiece
//   S2_1(x) = r(x) + m(x)            (2)   first scan, reference piece
//   S2_2(x) = r(x + d) + m(x)        (3)   second scan, reference piece traversed by -d
//
// so S2_2 - S2_1 = r(x + d) - r(x) (Eq. 4) and r follows by summing these first differences from
// an initial value r(x_1) (Eq. 9), then m = S2_1 - r (Eq. 2) and w = S1_1 - m (Eq. 1).
//
// d must be an integer multiple p of the sampling interval Δx; a non-integer multiple is rejected
// (no interpolation: r between samples is unknown, and interpolating it would bias the differences
// by the curvature of r).  For p > 1 the differences link only samples p apart, so r splits into
// p interleaved chains, each with its own unknown initial value; see ChainJoin.
#include <Eigen/Core>
#include <limits>
#include <string>

namespace errsep::core {

/// How the p = d/Δx interleaved chains of Eq. (9) are given their initial values when p > 1.
enum class ChainJoin {
  /// Chain j starts at r(x_j) = initial_um for every j (the p - 1 extra initial values are taken as
  /// known and equal to r(x_1); only correct for a reference piece whose first p samples are
  /// level).
  given_initial_values,
  /// Chain 0 starts at initial_um; the offsets of chains 1..p-1 are chosen to minimise the sum of
  /// squared first differences of r between neighbouring samples (a smoothness assumption on the
  /// reference piece, exact for a reference that is linear over the first p samples and close
  /// for any r that is smooth on the scale of d).  Documented extension, not in the paper.
  least_roughness,
};

struct DisplacementOptions {
  double sample_interval_mm = 5.0;  ///< Δx, spacing of the samples x_k
  double displacement_mm = 5.0;     ///< d, traverse of the reference piece between the scans
  double initial_um = 0.0;          ///< r(x_1) of Eq. (9) (the method fixes r only up to it)
  ChainJoin chain_join = ChainJoin::least_roughness;
  /// |d/Δx - round(d/Δx)| above this is "not an integer multiple" (covers decimal rounding of
  /// values read from files).
  double integer_tolerance = 1e-6;
  /// σ of one sensor reading for the joint estimate's uncertainty (displacement_joint.hpp); NaN:
  /// estimated from the redundant readings.
  double reading_sigma_um = std::numeric_limits<double>::quiet_NaN();
  /// Standard uncertainty of the traverse d (one draw per measurement; the paper's micrometer):
  /// its contribution is added to the joint estimate's uncertainty.  0 = d exact.
  double displacement_sigma_mm = 0.0;

  /// True if the options can be used; otherwise *why names the field, its value and the rule.
  bool is_valid(std::string* why = nullptr) const;
  /// p = d/Δx (valid options only).
  int step_ratio() const;
};

struct ReferenceResult {
  Eigen::VectorXd r_um;  ///< reference profile r(x_k), Eq. (9), same length as the scans
  Eigen::VectorXd m_um;  ///< motion error m(x_k) = S2_1 - r, Eq. (2)
  int step_ratio = 1;    ///< p = d/Δx
  int chains = 1;        ///< independent chains of Eq. (9) (= p)
};

struct DisplacementResult {
  Eigen::VectorXd r_um;  ///< reference profile r(x_k), Eq. (9)
  Eigen::VectorXd m_um;  ///< motion error m(x_k), Eq. (2)
  Eigen::VectorXd w_um;  ///< workpiece profile w(x_k) = S1_1 - m, Eq. (1)
  int step_ratio = 1;
  int chains = 1;
  /// One line: sample count, p, chain handling, ranges of r, m, w.
  std::string brief_report() const;
};

/// Reference profile and motion error from the two scans of one reference-piece sensor (Eqs. 2-9).
/// s_first = S2_1(x_k), s_second = S2_2(x_k), k = 0..n-1 at spacing Δx.  The last p samples of
/// s_second (which see r beyond x_{n-1}) are not needed for r on the scan range and are ignored.
/// Throws std::invalid_argument on invalid options, unequal lengths, n <= p, or non-finite input.
ReferenceResult separate_reference(const Eigen::VectorXd& s_first_um,
                                   const Eigen::VectorXd& s_second_um,
                                   const DisplacementOptions& opts);

/// Offsets c_1..c_{p−1} (c_0 = 0) of the chains k mod p of r (r_k += c_{k mod p}) that minimise
/// the sum of squared first differences of r (ChainJoin::least_roughness).  Empty for p = 1.
Eigen::VectorXd least_roughness_offsets(const Eigen::VectorXd& r_um, int p);

/// The full one-axis method, Eqs. (1)-(9).  s1_first = S1_1 (workpiece), s2_first = S2_1,
/// s2_second = S2_2 (reference piece).  Throws std::invalid_argument as separate_reference.
DisplacementResult separate_displacement(const Eigen::VectorXd& s1_first_um,
                                         const Eigen::VectorXd& s2_first_um,
                                         const Eigen::VectorXd& s2_second_um,
                                         const DisplacementOptions& opts);

}  // namespace errsep::core
