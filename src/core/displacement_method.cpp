#include "errsep/core/displacement_method.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace errsep::core {

bool DisplacementOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (!(std::isfinite(sample_interval_mm) && sample_interval_mm > 0))
    return fail("sample_interval_mm = " + std::to_string(sample_interval_mm) +
                ": must be finite and > 0");
  if (!(std::isfinite(displacement_mm) && displacement_mm > 0))
    return fail("displacement_mm = " + std::to_string(displacement_mm) +
                ": must be finite and > 0 (the reference piece must be traversed)");
  if (!std::isfinite(initial_um))
    return fail("initial_um = " + std::to_string(initial_um) + ": must be finite");
  if (!(integer_tolerance >= 0 && integer_tolerance < 0.5))
    return fail("integer_tolerance = " + std::to_string(integer_tolerance) +
                ": must be in [0, 0.5)");
  if (!std::isnan(reading_sigma_um) && !(std::isfinite(reading_sigma_um) && reading_sigma_um > 0))
    return fail("reading_sigma_um = " + std::to_string(reading_sigma_um) +
                ": must be > 0 (or NaN: estimated from the redundant readings)");
  if (!(std::isfinite(displacement_sigma_mm) && displacement_sigma_mm >= 0))
    return fail("displacement_sigma_mm = " + std::to_string(displacement_sigma_mm) +
                ": must be finite and >= 0");
  const double ratio = displacement_mm / sample_interval_mm;
  if (std::abs(ratio - std::round(ratio)) > integer_tolerance || std::round(ratio) < 1) {
    std::ostringstream s;
    s << "displacement_mm = " << displacement_mm << " is not an integer multiple of the sampling "
      << "interval " << sample_interval_mm << " mm (d/dx = " << ratio
      << "); the displacement method needs d = p*dx with integer p >= 1 (Eq. 8)";
    return fail(s.str());
  }
  return true;
}

int DisplacementOptions::step_ratio() const {
  return static_cast<int>(std::lround(displacement_mm / sample_interval_mm));
}

Eigen::VectorXd least_roughness_offsets(const Eigen::VectorXd& r, int p) {
  if (p <= 1) return {};
  // Offsets c_j (j = 1..p-1; c_0 = 0) minimising sum_k (r_{k+1} + c_{(k+1)%p} - r_k - c_{k%p})^2:
  // a (p-1)-unknown linear least-squares problem, solved densely (p is small).
  const Eigen::Index n = r.size();
  const Eigen::Index rows = n - 1;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, p - 1);
  Eigen::VectorXd b(rows);
  for (Eigen::Index k = 0; k + 1 < n; ++k) {
    const int j0 = static_cast<int>(k % p), j1 = static_cast<int>((k + 1) % p);
    if (j1 > 0) a(k, j1 - 1) += 1.0;
    if (j0 > 0) a(k, j0 - 1) -= 1.0;
    b(k) = -(r(k + 1) - r(k));
  }
  return a.colPivHouseholderQr().solve(b);
}

ReferenceResult separate_reference(const Eigen::VectorXd& s_first_um,
                                   const Eigen::VectorXd& s_second_um,
                                   const DisplacementOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("displacement method: " + why);
  const Eigen::Index n = s_first_um.size();
  if (s_second_um.size() != n)
    throw std::invalid_argument("displacement method: first scan has " + std::to_string(n) +
                                " samples, second scan " + std::to_string(s_second_um.size()));
  const int p = opts.step_ratio();
  if (n <= p)
    throw std::invalid_argument("displacement method: " + std::to_string(n) +
                                " samples do not reach beyond d/dx = " + std::to_string(p));
  if (!s_first_um.allFinite() || !s_second_um.allFinite())
    throw std::invalid_argument("displacement method: non-finite sensor reading");

  ReferenceResult res;
  res.step_ratio = p;
  res.chains = p;
  // Eq. (4)/(9): D_k = S2_2(x_k) - S2_1(x_k) = r(x_{k+p}) - r(x_k); each residue class k mod p
  // is one chain, summed from its first sample.
  Eigen::VectorXd r = Eigen::VectorXd::Zero(n);
  for (Eigen::Index k = p; k < n; ++k)
    r(k) = r(k - p) + (s_second_um(k - p) - s_first_um(k - p));

  if (p > 1 && opts.chain_join == ChainJoin::least_roughness) {
    const Eigen::VectorXd c = least_roughness_offsets(r, p);
    for (Eigen::Index k = 0; k < n; ++k) {
      const int j = static_cast<int>(k % p);
      if (j > 0) r(k) += c(j - 1);
    }
  }
  r.array() += opts.initial_um;
  res.r_um = std::move(r);
  res.m_um = s_first_um - res.r_um;  // Eq. (2)
  return res;
}

DisplacementResult separate_displacement(const Eigen::VectorXd& s1_first_um,
                                         const Eigen::VectorXd& s2_first_um,
                                         const Eigen::VectorXd& s2_second_um,
                                         const DisplacementOptions& opts) {
  if (s1_first_um.size() != s2_first_um.size())
    throw std::invalid_argument("displacement method: workpiece scan has " +
                                std::to_string(s1_first_um.size()) + " samples, reference scan " +
                                std::to_string(s2_first_um.size()));
  if (!s1_first_um.allFinite())
    throw std::invalid_argument("displacement method: non-finite workpiece reading");
  ReferenceResult ref = separate_reference(s2_first_um, s2_second_um, opts);
  DisplacementResult res;
  res.w_um = s1_first_um - ref.m_um;  // Eq. (1)
  res.r_um = std::move(ref.r_um);
  res.m_um = std::move(ref.m_um);
  res.step_ratio = ref.step_ratio;
  res.chains = ref.chains;
  return res;
}

std::string DisplacementResult::brief_report() const {
  std::ostringstream s;
  auto range = [&](const char* name, const Eigen::VectorXd& v) {
    s << ", " << name << " in [" << (v.size() ? v.minCoeff() : 0.0) << ", "
      << (v.size() ? v.maxCoeff() : 0.0) << "] um";
  };
  s << "displacement method: " << r_um.size() << " samples, d/dx = " << step_ratio << " (" << chains
    << (chains == 1 ? " chain)" : " chains)");
  range("r", r_um);
  range("m", m_um);
  range("w", w_um);
  return s.str();
}

}  // namespace errsep::core
