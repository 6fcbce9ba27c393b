#include "errsep/core/reference_comparison.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace errsep::core {

bool ReferenceCompareOptions::is_valid(std::string* why) const {
  if (min_points < 1 || (alignment == ReferenceAlignment::line && min_points < 3)) {
    if (why)
      *why = "min_points = " + std::to_string(min_points) +
             ": must be >= 3 for a line alignment (>= 1 otherwise)";
    return false;
  }
  return true;
}

ReferenceComparison compare_with_reference(const Eigen::VectorXd& x_mm,
                                           const Eigen::VectorXd& measured,
                                           const Eigen::VectorXd& x_ref_mm,
                                           const Eigen::VectorXd& ref,
                                           const ReferenceCompareOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("reference comparison: " + why);
  if (x_mm.size() != measured.size())
    throw std::invalid_argument("reference comparison: " + std::to_string(x_mm.size()) +
                                " positions but " + std::to_string(measured.size()) + " values");
  if (x_ref_mm.size() != ref.size())
    throw std::invalid_argument("reference comparison: reference has " +
                                std::to_string(x_ref_mm.size()) + " positions but " +
                                std::to_string(ref.size()) + " values");
  if (x_ref_mm.size() < 2)
    throw std::invalid_argument("reference comparison: the reference needs at least 2 points");
  if (!x_mm.allFinite() || !measured.allFinite() || !x_ref_mm.allFinite() || !ref.allFinite())
    throw std::invalid_argument("reference comparison: non-finite value");
  for (Eigen::Index j = 1; j < x_ref_mm.size(); ++j)
    if (!(x_ref_mm(j) > x_ref_mm(j - 1)))
      throw std::invalid_argument("reference comparison: reference x must increase (point " +
                                  std::to_string(j + 1) + ")");

  ReferenceComparison out;
  std::vector<double> xs, rs, ms;
  const double* xb = x_ref_mm.data();
  const double* xe = xb + x_ref_mm.size();
  for (Eigen::Index n = 0; n < x_mm.size(); ++n) {
    const double x = x_mm(n);
    if (x < x_ref_mm(0) || x > x_ref_mm(x_ref_mm.size() - 1)) {
      ++out.points_outside;
      continue;
    }
    // Linear interpolation between the bracketing reference samples.
    auto hi = std::lower_bound(xb, xe, x);
    Eigen::Index j = hi - xb;
    double r;
    if (x_ref_mm(j) == x) {
      r = ref(j);
    } else {
      const double t = (x - x_ref_mm(j - 1)) / (x_ref_mm(j) - x_ref_mm(j - 1));
      r = (1.0 - t) * ref(j - 1) + t * ref(j);
    }
    xs.push_back(x);
    rs.push_back(r);
    ms.push_back(measured(n));
  }
  out.points = static_cast<int>(xs.size());
  if (out.points < opts.min_points)
    throw std::invalid_argument("reference comparison: only " + std::to_string(out.points) +
                                " scan positions lie inside the reference's x range [" +
                                std::to_string(x_ref_mm(0)) + ", " +
                                std::to_string(x_ref_mm(x_ref_mm.size() - 1)) + "] mm; need " +
                                std::to_string(opts.min_points));
  const auto n = static_cast<Eigen::Index>(xs.size());
  out.x_mm = Eigen::Map<const Eigen::VectorXd>(xs.data(), n);
  out.reference = Eigen::Map<const Eigen::VectorXd>(rs.data(), n);
  out.measured = Eigen::Map<const Eigen::VectorXd>(ms.data(), n);
  const Eigen::VectorXd d = out.measured - out.reference;
  switch (opts.alignment) {
    case ReferenceAlignment::line: {
      // Least 2-norm of the difference over offset and slope (x centred for conditioning).
      const double xc = out.x_mm.mean();
      Eigen::MatrixXd A(n, 2);
      A.col(0).setOnes();
      A.col(1) = out.x_mm.array() - xc;
      const Eigen::Vector2d c = A.colPivHouseholderQr().solve(d);
      out.slope_per_mm = c(1);
      out.offset = c(0) - c(1) * xc;
      break;
    }
    case ReferenceAlignment::offset:
      out.offset = d.mean();
      break;
    case ReferenceAlignment::none:
      break;
  }
  out.difference = d.array() - out.offset - out.slope_per_mm * out.x_mm.array();
  out.rms = std::sqrt(out.difference.squaredNorm() / static_cast<double>(n));
  out.max_abs = out.difference.cwiseAbs().maxCoeff();
  return out;
}

}  // namespace errsep::core
