#pragma once
// Gross errors in a four-sensor scan (issue 16, item 3): an electrical spike (one reading off by
// many σ) and a knocked sensor (every reading of one configuration from some position on offset
// by a constant), found robustly and kept out of S.
//
// Both are linear effects with a column z in reading space: a spike at reading (n, c) is the unit
// vector of that reading (the mean-shift outlier model: adding it to a least-squares model is
// deleting the reading), a step of configuration c at position k is 1 on the readings (n >= k, c).
// Under the model `space` (residual_analysis.hpp) the residual r = Π·y gives for each candidate
// the standardised size t_z = (Π z)ᵀ r / (σ̃‖Π z‖), with σ̃ = 1.4826·median_{n,c} |r_nc|/√d_nc the
// MAD scale of the readings' standardised residuals (d_nc the reading-space projector's
// diagonal): a spike or step inflates σ̂ but barely moves the median, so it cannot hide itself.
// A step's t uses σ̂ of the model with that step in it instead (the likelihood ratio of a
// change-point): a step moves most readings' residuals and would inflate a MAD.
// For a spike, t is the internally studentised residual (of all readings at one position, the
// spike's own is the largest: |P_ij|/√P_jj <= √P_ii for a projector).  A step's candidates are the
// change-points of a CUSUM of one configuration's residual, here in projected form.
//
// The largest |t| of each kind over all candidates is tested against its distribution under the
// model, found by Monte-Carlo draws of Π·ε (exact for Gaussian noise, scale-free since σ̃ scales
// with the noise), at α/2 per kind.  A detection adds its column to the model and the search goes
// on (at most max_errors), so several spikes, or a spike and a step, are found one after the
// other.  The sizes of all found errors are then fitted jointly with their covariance.
//
// separate_without_gross_errors redoes the separation on the readings minus the fitted errors
// (a spike's reading replaced by what the model predicts, a step given its own offset), keeps the
// gauge of the separation of the raw readings (a step never moves what the data cannot see, as in
// refine.hpp) and carries the fitted sizes' covariance into u_S, u_γ, u_f.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/residual_analysis.hpp"
#include "errsep/core/step_decision.hpp"

namespace errsep::core {

/// A step whose configuration and place another measurement determined.
struct AttributedStep {
  int configuration = 0;  ///< 0-based
  int position = 0;       ///< first position of the step
  double size_um = 0;     ///< its size there (the sign is not used: only |size| bounds the bias)
  double u_size_um = 0;   ///< its standard uncertainty
  std::string by = "another measurement";  ///< for the report line
};

struct GrossErrorOptions {
  double alpha = 0.01;      ///< per round, split between spikes and steps
  int max_errors = 6;       ///< stop after this many detections
  int min_segment = 3;      ///< a step leaves at least this many positions on each side
  int mc_samples = 400;     ///< Monte-Carlo draws per round
  std::uint64_t seed = 13;  ///< fixed: the same data give the same report
  /// An error is removed only when its column explains the residual better than the best one of
  /// another configuration by this much (likelihood ratio, χ²₁ quantile; 6.63 is its 99 %).
  double attribution_chi2 = 6.63;
  /// … and only when its statistic exceeds the detection threshold by this much (near the
  /// threshold the largest candidate is mostly noise and its fitted size inflated).
  double apply_margin = 1.0;
  /// A step is taken for a knocked sensor only when it explains the residual better than a smooth
  /// drift of any one configuration (a cubic in position, i.e. in time within the traverse) by this
  /// much (likelihood ratio of the step added to the smooth model, χ²₁ quantile; 6.63 is its
  /// 99 %): a thermal drift of one sensor also fits a step at the middle of its ramp.
  double smooth_chi2 = 6.63;
  /// Steps another measurement names (find_repeat_steps, repeat_steps.hpp): each goes into the
  /// model first, whether or not this scan alone shows it, and is removed or carried like a found
  /// one (separate_without_gross_errors).
  std::vector<AttributedStep> attributed_steps;
  /// Spikes of one configuration within this many positions of each other (a gap of at most
  /// cluster_positions − 1 readings) are a shape along x, not electrical spikes, and are not
  /// removed: their sizes go into u (find_gross_errors).  0: every spike stands alone.
  int cluster_positions = 2;
  bool is_valid(std::string* why = nullptr) const;
};

enum class GrossErrorKind { spike, step };
const char* to_string(GrossErrorKind k);

/// A place the error may be: a configuration whose own best candidate explains the residual
/// within attribution_chi2 of the best one, with the size that candidate would have.
struct GrossErrorAlternative {
  int configuration = 0;  ///< 0-based
  int position = 0;       ///< the spike's position, or the step's first position
  double size_um = 0, u_size_um = 0;
};

struct GrossError {
  GrossErrorKind kind = GrossErrorKind::spike;
  int configuration = 0;  ///< 0-based
  int position = 0;       ///< the spike's position index, or the first position of the step
  double x_mm = 0;
  double size_um = 0, u_size_um = 0;  ///< from the joint fit of all found errors
  double robust_z = 0;                ///< |t| when it was found
  double p_value = 1;                 ///< Monte-Carlo p-value of that largest |t|
  double z_critical = 0;  ///< the detection threshold of its round (null quantile at α/2)
  double rival_z = 0;     ///< |t| of the best candidate of another configuration in that round
  /// Where it may be, the best first; one entry when attributed to one configuration.  A step's
  /// candidates in different configurations differ only in the few positions between their
  /// offsets (the rest is the same residual direction, see the file comment), so several often
  /// remain; an error with more than one is never removed, and each alternative's column is
  /// carried into u (separate_without_gross_errors).
  std::vector<GrossErrorAlternative> alternatives;
  std::string attributed_by;  ///< what named it, when not this scan alone
  double known_size_um = 0;   ///< |size| that measurement gave (bounds the bias when left in)
  double known_u_size_um = 0;
  /// For a step: how much better the step explains the residual than a smooth drift of any one
  /// configuration does (the smallest over the four) (the likelihood ratio of the step added to a
  /// cubic in position of that configuration's readings, χ²₁ units;
  /// GrossErrorOptions::smooth_chi2).  Below the threshold it is reported as a smooth change (a
  /// drift), not a knocked sensor, and not removed.
  double step_over_smooth_chi2 = 0;
  bool smooth = false;           ///< a smooth drift explains it as well (the line above)
  int smooth_configuration = 0;  ///< the configuration whose smooth drift explains it best
  /// Largest widening of u_S it causes when not removed (0: not computed).
  double u_S_added_um = 0;
  bool applied = true;      ///< removed from the separation
  std::string not_applied;  ///< why not (attribution ambiguous, or removal would not help)
  std::string description;
};

struct GrossErrorScan {
  std::vector<GrossError> errors;
  double sigma_robust_um = 0;  ///< σ̃ of the first round
  double sigma_um = 0;         ///< σ̂ of the model with the errors in it
  Eigen::MatrixXd columns;     ///< 4P × K reading-space columns of the found errors (row 4n + i)
  Eigen::MatrixXd covariance;  ///< K × K of the sizes, µm²
  /// What separate_without_gross_errors carries into u: the covariance, plus the squared size of
  /// each error not removed that is attributed to one configuration (the bias of leaving it in);
  /// an ambiguous one is carried through each of its alternatives' columns instead.
  Eigen::MatrixXd carried;
  double attribution_chi2 = 6.63;     ///< of the search (for the report lines)
  Eigen::MatrixXd correction_um;      ///< P × 4: Σ size·column of the removed errors
  std::vector<std::string> findings;  ///< one line per error
  bool found() const { return !errors.empty(); }
};

/// Searches the residual of `m_um` (P × 4, corrected for any effects in the model) under `space`.
/// Throws std::invalid_argument for a shape mismatch or invalid options.
GrossErrorScan find_gross_errors(const ResidualSpace& space, const Eigen::MatrixXd& m_um,
                                 const GrossErrorOptions& opts = {});

/// The separation of `m_um` without the gross errors of `scan`.  Each error attributed to one
/// configuration is removed only when that makes S, γ and f better (decide_step,
/// step_decision.hpp, with its size's variance against the bias of leaving it in); the others
/// stay and their fitted size goes into u.  Updates the errors' `applied` and `not_applied`, the
/// scan's correction, carried covariance and findings.  The result has the gauge of `before`
/// (the separation of `m_um`) and u_S, u_γ, u_f widened by the carried covariance (sensitivities
/// from a separation at before's λ).  `before` when nothing was found.
FourSensorResult separate_without_gross_errors(const FourSensorConfig& cfg,
                                               const Eigen::MatrixXd& m_um, GrossErrorScan* scan,
                                               const FourSensorResult& before,
                                               const FourSensorOptions& solve,
                                               const StepDecisionOptions& decision = {});

}  // namespace errsep::core
