#pragma once
// Internal to the displacement loops (displacement_refine.cpp, displacement_refine_one_axis.cpp):
// the least-squares fit of a few effect columns to the redundancy's residual, and the forward
// selection both loops make with it.
//
// Forward selection: in each round every identifiable candidate of a family not yet taken is
// tried with the columns of those taken; candidates are ranked by what their columns explain
// beyond their number (Akaike: Δχ² − 2k, χ² in units of the candidate's residual variance), a
// candidate with a non-linear parameter (a thermal drift's τ, chosen from a grid) counting it as
// one more — ranked by F alone (or by p, which underflows to 0 for strong effects) the best of a τ
// grid beat a true linear drift by fitting the noise.  The winner is taken when its F-test (the
// extra parameter in its numerator degrees of freedom), Bonferroni-corrected over the candidates
// tried, is below α; otherwise selection stops.
#include <Eigen/Core>
#include <Eigen/QR>
#include <algorithm>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "errsep/core/step_decision.hpp"

namespace errsep::core::detail {

struct LsFit {
  Eigen::VectorXd beta;
  double rss = 0;
};

inline LsFit least_squares(const Eigen::MatrixXd& X, const Eigen::VectorXd& y) {
  LsFit f;
  if (X.cols() == 0) {
    f.rss = y.squaredNorm();
    return f;
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(X);
  f.beta = qr.solve(y);
  f.rss = (y - X * f.beta).squaredNorm();
  return f;
}

struct SelectionCandidate {
  std::string family;
  bool identifiable = false;
  bool extra_parameter = false;  ///< a non-linear parameter chosen from a grid (τ)
};

struct Selected {
  std::size_t index = 0;      ///< into the candidates
  double F = 0, p_value = 1;  ///< p after Bonferroni
};

/// `columns(indices)`: the design matrix of those candidates' columns side by side, y.size()
/// rows; `dof0`: the residual's degrees of freedom before any column.
inline std::vector<Selected> forward_select(
    const std::vector<SelectionCandidate>& cands,
    const std::function<Eigen::MatrixXd(const std::vector<std::size_t>&)>& columns,
    const Eigen::VectorXd& y, int dof0, double alpha) {
  std::vector<Selected> out;
  std::vector<std::size_t> taken;
  for (;;) {
    const double rss_t = least_squares(columns(taken), y).rss;
    int tried = 0;
    double best_score = -std::numeric_limits<double>::infinity();
    Selected best;
    bool any = false;
    for (std::size_t i = 0; i < cands.size(); ++i) {
      const auto& c = cands[i];
      if (!c.identifiable) continue;
      if (std::any_of(taken.begin(), taken.end(),
                      [&](std::size_t t) { return cands[t].family == c.family; }))
        continue;
      ++tried;
      auto fx = taken;
      fx.push_back(i);
      const Eigen::MatrixXd X = columns(fx);
      const double rss = least_squares(X, y).rss;
      const int cols = static_cast<int>(X.cols() - columns(taken).cols());
      const int kc = cols + (c.extra_parameter ? 1 : 0);
      const int dof = dof0 - static_cast<int>(X.cols()) - (c.extra_parameter ? 1 : 0);
      if (dof <= 0 || !(rss > 0)) continue;
      const double F = ((rss_t - rss) / kc) / (rss / dof);
      const double score = (rss_t - rss) / (rss / dof) - 2.0 * kc;
      if (score > best_score) {
        best_score = score;
        best = {i, F, f_test_p_value(F, kc, dof)};
        any = true;
      }
    }
    if (tried == 0 || !any) break;
    best.p_value = std::min(1.0, best.p_value * tried);  // Bonferroni over the candidates tried
    if (!(best.p_value < alpha)) break;
    taken.push_back(best.index);
    out.push_back(best);
  }
  return out;
}

}  // namespace errsep::core::detail
