#pragma once
// Evaluation of separated motion errors in the terms of ISO 230-1 (test code for machine tools,
// geometric accuracy) and ISO 12780-1 / ISO 12781-1 (straightness and flatness: reference lines
// and planes, minimum zone).
//
// Inputs are the results of the four-sensor method (Zhao et al. 2019: straightness S(x) in um,
// tilt gamma(x)) and of the displacement method (Haramiishi et al. 2024: surface w(x, y) and
// motion error m(x, y) in um).  Every figure comes with an expanded uncertainty U = k * u_c
// propagated from the per-point standard uncertainties of the profile.
//
// Uncertainty propagation (GUM / JCGM 102, the profile is a vector result):
//   each figure T (a straightness, a flatness, an angular deviation) is, at the solution, a
//   linear function of the profile values: T = sum_i c_i p_i, with the active points (the
//   extreme deviations and, for end-point/least-squares/minimum-zone, the points that fix the
//   reference) held fixed.  The sensitivity vector c is returned with every result, so a caller
//   that has the full covariance matrix V of the profile (e.g. the covariance of the regularised
//   four-sensor estimate) can form u_c = sqrt(c^T V c) with propagate_covariance().
//   With only per-point standard uncertainties u_i, the correlation is unknown; two numbers are
//   given:
//     u_uncorrelated = sqrt(sum c_i^2 u_i^2)   (V = diag(u^2))
//     u_bound        = sum |c_i| u_i            (an upper bound of sqrt(c^T V c) for ANY
//                                                correlation matrix, by Cauchy-Schwarz)
//   The expanded uncertainty uses the model chosen in EvaluationOptions::correlation (default:
//   the bound, because points of a regularised estimate are strongly correlated and we do not
//   know the sign of the correlation between the active points).
// Limits of this linearisation: max - min of a noisy profile is biased upward (extreme-value
// statistics), and the active set may switch when extreme points are nearly tied; the reported U
// covers the propagated input uncertainty only, not that bias.
#include <Eigen/Dense>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace errsep::core {

/// Reference straight line of a straightness evaluation (ISO 230-1 3.4.8 / ISO 12780-1).
enum class ReferenceLine {
  end_points,     ///< line through the first and last measured points
  least_squares,  ///< least-squares line (minimises sum of squared vertical deviations)
  minimum_zone,   ///< minimum zone: two parallel lines of smallest vertical separation
};
/// "end_points", "least_squares", "minimum_zone".
const char* to_string(ReferenceLine r);
/// The inverse of to_string, or nullopt.
std::optional<ReferenceLine> parse_reference_line(std::string_view s);
/// Human label, e.g. "end-point line".
const char* label(ReferenceLine r);

enum class ReferencePlane { least_squares, minimum_zone };
const char* to_string(ReferencePlane r);
const char* label(ReferencePlane r);

/// How per-point standard uncertainties are combined (see the file comment).
enum class Correlation {
  uncorrelated,  ///< u_c = sqrt(sum c_i^2 u_i^2)
  bound,         ///< u_c = sum |c_i| u_i, valid for any correlation (conservative)
};
const char* to_string(Correlation c);

struct EvaluationOptions {
  Correlation correlation = Correlation::bound;
  double coverage_factor = 2.0;  ///< k of U = k u_c (k = 2, about 95 %)
  bool is_valid(std::string* why) const;
};

/// Line v(x) = offset_um + slope_um_per_mm * x_mm.
struct Line {
  double offset_um = 0;
  double slope_um_per_mm = 0;
  double at(double x_mm) const { return offset_um + slope_um_per_mm * x_mm; }
};

/// Plane v(x, y) = offset_um + slope_x_um_per_mm * x_mm + slope_y_um_per_mm * y_mm.
struct Plane {
  double offset_um = 0;
  double slope_x_um_per_mm = 0;
  double slope_y_um_per_mm = 0;
  double at(double x_mm, double y_mm) const {
    return offset_um + slope_x_um_per_mm * x_mm + slope_y_um_per_mm * y_mm;
  }
};

/// Uncertainty of one figure, from its sensitivity vector.
struct FigureUncertainty {
  double u_uncorrelated = 0;  ///< standard uncertainty with V = diag(u^2)
  double u_bound = 0;         ///< standard uncertainty bound for any correlation
  double expanded = 0;        ///< U = k * (u by the chosen Correlation model)
  double coverage_factor = 2;
};

struct StraightnessResult {
  ReferenceLine reference = ReferenceLine::least_squares;
  /// Reference line.  For the minimum zone it is the mid-line of the zone.
  Line line;
  double straightness_um = 0;  ///< max - min of the deviations from the reference line
  FigureUncertainty uncertainty;
  std::size_t index_max = 0;  ///< sample with the largest deviation
  std::size_t index_min = 0;  ///< sample with the smallest deviation
  /// dT/dS_i at the solution (sums to 0 and is orthogonal to x: a figure about a reference line
  /// does not change when a line is added to the profile).
  std::vector<double> sensitivity;
};

/// Straightness of a profile s_um(x_mm) about the chosen reference line.  x must be strictly
/// increasing, at least 2 points; u_um holds per-point standard uncertainties (k = 1) or is empty
/// (then the uncertainty is 0).  Throws std::invalid_argument naming the problem.
/// Minimum zone: exact for the polyline.  The zone width as a function of the slope b,
///   W(b) = max_i (s_i - b x_i) - min_i (s_i - b x_i),
/// is convex and piecewise linear with breakpoints only at slopes of convex-hull edges, so its
/// minimum is attained at one of those slopes; every hull-edge slope is evaluated (O(N * H)).
StraightnessResult evaluate_straightness(const std::vector<double>& x_mm,
                                         const std::vector<double>& s_um,
                                         const std::vector<double>& u_um, ReferenceLine reference,
                                         const EvaluationOptions& opts = {});

/// Straightness of an estimated profile whose errors are correlated along it (a separation),
/// with U from the full covariance rather than per-point u.  Straightness is max − min about a
/// fitted line, a convex function of the profile: noise in the profile biases it upward, the
/// more the larger the noise is against the profile's own shape.  That bias is estimated by
/// Monte Carlo (JCGM 101: the mean change of the figure over draws of the profile's error) and
/// removed; the corrected figure is clipped at 0 (a zone width is never negative).  U is k·u,
/// u² the larger of cᵀVc (c the sensitivity at the points that fix the zone) and the variance of
/// the draws' figures (larger where the noise chooses those points: cᵀVc alone understated u up
/// to 2.6× at N = 5000; issue 15), plus the bias's Monte Carlo error var/draws.  Measured on
/// random profiles (tests/core/four_sensor_coverage.cpp), the corrected figure lies within U of
/// the truth's in 90–99 % of runs at every scan length, where the uncorrected one with the same
/// U was off in up to 13 % and a pure Monte Carlo interval, which needs the error model's shape
/// to be exact, in up to 100 %.
struct StraightnessEstimate {
  StraightnessResult zone;     ///< of the estimated profile (reference line, active points)
  double straightness_um = 0;  ///< max(0, zone.straightness_um − bias_um)
  double bias_um = 0;          ///< Monte Carlo mean of T(s + draw) − T(s)
  double u_um = 0;             ///< standard uncertainty sqrt(cᵀVc)
  double expanded_um = 0;      ///< U = k·u
  int draws = 0;
};
/// Var(cᵀs) for a sensitivity vector c over the profile's points.
using ProfileVariance = std::function<double(const std::vector<double>& c)>;
/// Fills `deviation` (profile size) with one draw of (truth − estimate) for the given seed.
using ProfileSampler = std::function<void(std::uint64_t seed, std::vector<double>& deviation)>;

/// The straightness of `s_um` about `reference` with the bias correction and U described above.
/// Throws std::invalid_argument as evaluate_straightness, or for draws < 20.
StraightnessEstimate estimate_straightness(const std::vector<double>& x_mm,
                                           const std::vector<double>& s_um,
                                           const ProfileVariance& variance,
                                           const ProfileSampler& sampler, ReferenceLine reference,
                                           int draws = 100, std::uint64_t seed = 1,
                                           const EvaluationOptions& opts = {});

struct LocalStraightnessResult {
  double local_length_mm = 0;
  ReferenceLine reference = ReferenceLine::least_squares;
  double straightness_um = 0;     ///< largest straightness over all windows of local_length_mm
  FigureUncertainty uncertainty;  ///< of the window that gave the largest value
  double window_start_mm = 0;     ///< that window
  double window_end_mm = 0;
  std::size_t windows = 0;  ///< number of windows evaluated
};

/// Local straightness (ISO 230-1: straightness over a given length anywhere in the travel): for
/// every sample x_s with x_s + local_length_mm <= x_max, the straightness of the samples in
/// [x_s, x_s + local_length_mm] about the chosen reference line; the largest is reported.
/// local_length_mm must be > 0 and at most the measured length.
LocalStraightnessResult evaluate_local_straightness(const std::vector<double>& x_mm,
                                                    const std::vector<double>& s_um,
                                                    const std::vector<double>& u_um,
                                                    double local_length_mm, ReferenceLine reference,
                                                    const EvaluationOptions& opts = {});

struct AngularResult {
  double deviation_urad = 0;    ///< max - min of the angle over the travel
  double deviation_arcsec = 0;  ///< the same in arc seconds
  double max_urad = 0, min_urad = 0;
  std::size_t index_max = 0, index_min = 0;
  FigureUncertainty uncertainty;  ///< in urad
  double expanded_uncertainty_arcsec = 0;
};

/// Angular deviation (ISO 230-1 3.4.x: max - min of the angular error motion over the travel),
/// from gamma(x) in urad with per-point standard uncertainties in urad (or empty).
AngularResult evaluate_angular_deviation(const std::vector<double>& gamma_urad,
                                         const std::vector<double>& u_urad,
                                         const EvaluationOptions& opts = {});

struct FlatnessResult {
  ReferencePlane reference = ReferencePlane::least_squares;
  Plane plane;  ///< least-squares plane, or the mid-plane of the minimum zone
  double flatness_um = 0;
  FigureUncertainty uncertainty;
  std::size_t index_max = 0, index_min = 0;
  std::vector<double> sensitivity;  ///< dT/dw_i
  std::size_t iterations = 0;       ///< simplex pivots (minimum zone)
  bool converged = true;            ///< false only if the pivot limit was hit (then T is an upper
                                    ///< bound of the minimum-zone flatness)
};

/// Flatness of w_um(x_mm, y_mm) (one value per grid node or scattered point; at least 3 points
/// not on one line).  Least squares: the usual normal equations.  Minimum zone: the Chebyshev
/// (L-infinity) plane fit, solved exactly as a linear programme by a revised simplex method on
/// its dual (4 rows: the basis is a 4x4 matrix; the entering point is the one with the largest
/// deviation, i.e. the Stiefel exchange; Bland's rule takes over if it stalls).
FlatnessResult evaluate_flatness(const std::vector<double>& x_mm, const std::vector<double>& y_mm,
                                 const std::vector<double>& w_um, const std::vector<double>& u_um,
                                 ReferencePlane reference, const EvaluationOptions& opts = {});

/// u_c = sqrt(c^T V c) for a full covariance matrix V (um^2) of the profile.
double propagate_covariance(const std::vector<double>& sensitivity, const Eigen::MatrixXd& cov);

/// Combines a sensitivity vector with per-point standard uncertainties (see the file comment).
FigureUncertainty propagate(const std::vector<double>& sensitivity, const std::vector<double>& u,
                            const EvaluationOptions& opts);

// ---- ISO 230-1 error symbols ------------------------------------------------------------------
// E<error direction><moving axis>: EXX positioning of X, EYX straightness of X in Y direction,
// EAX/EBX/ECX angular error motions of X about the X (roll), Y (pitch/yaw) and Z axes.

/// Straightness of `moving_axis` in `direction`, e.g. ('X','Y') -> "EYX".  Axes are X, Y or Z
/// (case-insensitive) and must differ.  Throws std::invalid_argument otherwise.
std::string straightness_symbol(char moving_axis, char direction);
/// Angular error motion of `moving_axis` in the plane of its travel and `direction` (the tilt of
/// the four-sensor method), i.e. rotation about the third axis: ('X','Y') -> "ECX",
/// ('X','Z') -> "EBX", ('Y','X') -> "ECY".
std::string angular_symbol(char moving_axis, char direction);
/// Positioning error of an axis, e.g. 'X' -> "EXX".
std::string positioning_symbol(char axis);

constexpr double kArcsecPerUrad = 180.0 * 3600.0 / 3.14159265358979323846 * 1e-6;
constexpr double kUradPerDeg = 3.14159265358979323846 / 180.0 * 1e6;

}  // namespace errsep::core
