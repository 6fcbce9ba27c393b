#pragma once
// Measure - compensate - verify: a first scan measures the error, a table compensates it, a
// second scan on the compensated machine measures what is left.
//
//   before     e_b(p)          the first scan's error at machine positions p (S through the axes)
//   predicted  e_b(p) + c(p)   what the table leaves, c as the controller applies it
//   measured   e_a(p)          the second scan's error
//
// Each gets its straightness (minimum zone, ISO 230-1) with its expanded uncertainty U (the
// first scan's u for the prediction: the table is a fixed function).  The measured residual is
// consistent with the prediction when |T_measured - T_predicted| <= U_measured + U_predicted.
// Point by point, d(p) = e_a - (e_b + c) less its least-squares line (the artefact's alignment
// and S's constant are not the machine's) is compared with k sqrt(u_a^2 + u_b^2); the share of
// points inside is reported (about 95 % when the stated u are right).
#include <functional>
#include <vector>

#include "errsep/core/iso230.hpp"
#include "errsep/core/machine_axes.hpp"

namespace errsep::core {

/// An error at machine positions: e = reading_sign * S, positions increasing, no line removed.
struct MachineError {
  std::vector<double> position_mm;
  std::vector<double> e_um;
  std::vector<double> u_um;  ///< standard uncertainty per point, or empty
};

/// The error of a separated S(x) (x from the scan start) in machine coordinates.
MachineError machine_error(const std::vector<double>& x_mm, const std::vector<double>& s_um,
                           const std::vector<double>& u_s_um, const MachineAxes& axes);

struct VerificationResult {
  StraightnessResult before, predicted, measured;  ///< minimum zone, with U
  double difference_um = 0;                        ///< T_measured - T_predicted
  double allowed_um = 0;                           ///< U_measured + U_predicted
  bool consistent = false;                         ///< |difference| <= allowed
  double ratio = 0;                                ///< T_measured / T_before
  double pointwise_coverage = 0;  ///< share of points with |d - line| <= k sqrt(u_a^2 + u_b^2)
  std::size_t points = 0;         ///< common positions compared
  // The profiles at the common positions (for the report and its CSV).
  std::vector<double> position_mm, e_before_um, u_before_um, e_predicted_um, e_measured_um,
      u_measured_um;
};

/// `comp_um(p)`: the compensation the controller applies at machine position p.  The two scans
/// are compared at the first scan's positions inside the second's range (the second interpolated
/// linearly).  Throws std::invalid_argument when they share fewer than 3 positions.
VerificationResult verify_compensation(const MachineError& before, const MachineError& after,
                                       const std::function<double(double)>& comp_um,
                                       const EvaluationOptions& opts = {});

}  // namespace errsep::core
