#pragma once
// Comparison of a separated profile with an independent reference trace (a laser interferometer
// or CMM trace of the same slideway), the check of Zhao et al. 2019 section 4 (Fig. 11).
//
// The two instruments measure in different coordinate systems: the interferometer's O_mX_mY_m and
// the four-sensor system's OXY differ by a rotation (and a zero).  The paper therefore rotates OXY
// so that the 2-norm of S_l − S_a is least before comparing.  For a small rotation θ this adds
// θ·x (plus a constant) to S, so the alignment is the least-squares line of the difference; for
// the tilt γ a rotation is a constant, so only the mean is removed.  The reference is given on its
// own x grid: it is interpolated (linearly, no extrapolation) to the scan's positions, and the
// positions outside its range are left out of the comparison.
#include <Eigen/Core>
#include <string>

namespace errsep::core {

enum class ReferenceAlignment {
  line,    ///< remove the best-fit offset + slope (S, f: rotation of the coordinate system)
  offset,  ///< remove the mean (γ: a rotation is a constant tilt)
  none,
};

struct ReferenceCompareOptions {
  ReferenceAlignment alignment = ReferenceAlignment::line;
  int min_points = 3;  ///< fewer common positions is an error
  bool is_valid(std::string* why = nullptr) const;
};

struct ReferenceComparison {
  Eigen::VectorXd x_mm;        ///< scan positions inside the reference's range
  Eigen::VectorXd reference;   ///< the reference interpolated there
  Eigen::VectorXd measured;    ///< the separated profile there
  Eigen::VectorXd difference;  ///< measured − reference − the alignment line (what is left)
  double offset = 0;           ///< removed constant, in the profile's unit
  double slope_per_mm = 0;     ///< removed slope (profile unit per mm; µm/mm = mrad for S)
  double rms = 0;              ///< RMS of `difference`
  double max_abs = 0;          ///< max |difference|
  int points = 0;              ///< positions compared
  int points_outside = 0;      ///< scan positions outside the reference's x range
};

/// Compares `measured` (on x_mm, ascending) with the reference trace (x_ref_mm strictly
/// ascending, values ref).  Throws std::invalid_argument for mismatched lengths, non-finite
/// values, a reference x that does not increase, or fewer than min_points common positions.
ReferenceComparison compare_with_reference(const Eigen::VectorXd& x_mm,
                                           const Eigen::VectorXd& measured,
                                           const Eigen::VectorXd& x_ref_mm,
                                           const Eigen::VectorXd& ref,
                                           const ReferenceCompareOptions& opts = {});

}  // namespace errsep::core
