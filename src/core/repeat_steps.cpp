#include "errsep/core/repeat_steps.hpp"

#include <Eigen/QR>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <utility>

namespace errsep::core {

namespace {

// Detrending projector's complement applied by QR of the polynomial columns, and the normalised
// detrended step columns (P × K) with their first positions.
struct StepSearch {
  Eigen::MatrixXd Q;     // P × (degree + 1) orthonormal polynomial basis
  Eigen::MatrixXd W;     // P × K normalised detrended step columns
  Eigen::VectorXd norm;  // ‖detrended step column‖ per candidate
  std::vector<int> first;
  int dof = 0;  // P − degree − 1
};

StepSearch make_search(int P, int degree, int min_segment) {
  StepSearch s;
  Eigen::MatrixXd V(P, degree + 1);
  for (int n = 0; n < P; ++n) {
    const double u = P > 1 ? 2.0 * n / (P - 1) - 1.0 : 0.0;
    double p = 1.0;
    for (int d = 0; d <= degree; ++d, p *= u)
      V(n, d) = p;
  }
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(V);
  s.Q = qr.householderQ() * Eigen::MatrixXd::Identity(P, degree + 1);
  s.dof = P - degree - 1;
  std::vector<Eigen::VectorXd> cols;
  for (int k = min_segment; k <= P - min_segment; ++k) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(P);
    z.tail(P - k).setOnes();
    z -= s.Q * (s.Q.transpose() * z);
    if (z.norm() < 1e-9) continue;
    cols.push_back(z);
    s.first.push_back(k);
  }
  s.W.resize(P, static_cast<Eigen::Index>(cols.size()));
  s.norm.resize(static_cast<Eigen::Index>(cols.size()));
  for (std::size_t j = 0; j < cols.size(); ++j) {
    s.norm(static_cast<Eigen::Index>(j)) = cols[j].norm();
    s.W.col(static_cast<Eigen::Index>(j)) = cols[j] / cols[j].norm();
  }
  return s;
}

struct Best {
  double z = 0;
  int j = -1;
  double c = 0, sd = 0;
  std::size_t pair = 0;  // index into the list of differences
};

// The largest likelihood-ratio statistic of one difference over the candidates.
Best best_step(const StepSearch& s, const Eigen::VectorXd& d) {
  Best b;
  const Eigen::VectorXd r = d - s.Q * (s.Q.transpose() * d);
  const double rss = r.squaredNorm();
  const Eigen::VectorXd c = s.W.transpose() * r;
  for (Eigen::Index j = 0; j < c.size(); ++j) {
    const double rest = std::max(rss - c(j) * c(j), 1e-300);
    const double sd = std::sqrt(rest / std::max(1, s.dof - 1));
    const double z = std::abs(c(j)) / sd;
    if (z > b.z) b = {z, static_cast<int>(j), c(j), sd};
  }
  return b;
}

}  // namespace

bool RepeatStepOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(alpha > 0 && alpha < 1))
    return fail("alpha = " + std::to_string(alpha) + ": must be in (0, 1)");
  if (min_segment < 1)
    return fail("min_segment = " + std::to_string(min_segment) + ": must be >= 1");
  if (detrend_degree < 0)
    return fail("detrend_degree = " + std::to_string(detrend_degree) + ": must be >= 0");
  if (static_cast<double>(mc_samples + 1) * alpha <= 1.0)
    return fail("mc_samples = " + std::to_string(mc_samples) + " cannot reach alpha = " +
                std::to_string(alpha) + ": need mc_samples + 1 > 1/alpha");
  if (!(attribution_chi2 >= 0))
    return fail("attribution_chi2 = " + std::to_string(attribution_chi2) + ": must be >= 0");
  return true;
}

RepeatStepScan find_repeat_steps(const FourSensorConfig& cfg, const ScanSequence& seq,
                                 const Eigen::MatrixXd& m_um, const RepeatStepOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("invalid repeat step options: " + why);
  if (!seq.is_valid(&why)) throw std::invalid_argument("invalid scan sequence: " + why);
  const int P = cfg.positions(), T = seq.size();
  if (m_um.rows() != P || m_um.cols() != T)
    throw std::invalid_argument("find_repeat_steps: readings must be P x T = " + std::to_string(P) +
                                " x " + std::to_string(T));
  RepeatStepScan out;
  // Consecutive traverses of each configuration: (configuration, earlier, later).
  std::vector<std::array<int, 3>> pairs;
  for (int c = 0; c < 4; ++c) {
    int last = -1;
    for (int k = 0; k < T; ++k) {
      if (seq.traverses[static_cast<std::size_t>(k)].configuration != c) continue;
      if (last >= 0) pairs.push_back({c, last, k});
      last = k;
    }
    if (!pairs.empty() && pairs.back()[0] == c) out.repeated.push_back(c);
  }
  const StepSearch search = make_search(P, opts.detrend_degree, opts.min_segment);
  if (pairs.empty() || search.W.cols() == 0 || search.dof < 3) {
    out.not_tested = pairs.empty() ? "no configuration is measured twice in this plan"
                                   : "too few positions for a step search";
    return out;
  }
  auto statistics = [&](const Eigen::MatrixXd& m, std::array<Best, 4>* per_config,
                        std::size_t* best_pair) {
    double zmax = 0;
    for (std::size_t p = 0; p < pairs.size(); ++p) {
      const auto& [c, k0, k1] = pairs[p];
      Best b = best_step(search, m.col(k1) - m.col(k0));
      b.pair = p;
      if (per_config && b.z > (*per_config)[static_cast<std::size_t>(c)].z)
        (*per_config)[static_cast<std::size_t>(c)] = b;
      if (b.z > zmax) {
        zmax = b.z;
        if (best_pair) *best_pair = p;
      }
    }
    return zmax;
  };
  std::array<Best, 4> per{};
  std::size_t bp = 0;
  out.z = statistics(m_um, &per, &bp);
  std::mt19937_64 rng(opts.seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd draw(P, T);
  int ge = 0;
  for (int s = 0; s < opts.mc_samples; ++s) {
    for (Eigen::Index j = 0; j < draw.size(); ++j)
      draw.data()[j] = g(rng);
    if (statistics(draw, nullptr, nullptr) >= out.z) ++ge;
  }
  out.p_value = (1.0 + ge) / (1.0 + opts.mc_samples);
  out.found = out.p_value < opts.alpha;
  const int c = pairs[bp][0];
  const Best& b = per[static_cast<std::size_t>(c)];
  if (b.j < 0) {  // every difference is exactly a polynomial: nothing to locate
    out.found = false;
    return out;
  }
  out.configuration = c;
  out.earlier_traverse = pairs[b.pair][1];
  out.later_traverse = pairs[b.pair][2];
  out.position = search.first[static_cast<std::size_t>(b.j)];
  out.x_mm = out.position * cfg.dx_mm;
  const double nrm = search.norm(b.j);
  out.size_um = b.c / nrm;
  out.u_size_um = b.sd / nrm;
  for (int i = 0; i < 4; ++i)
    if (i != c) out.rival_z = std::max(out.rival_z, per[static_cast<std::size_t>(i)].z);
  out.attributed = out.z * out.z - out.rival_z * out.rival_z >= opts.attribution_chi2;
  if (out.found) {
    char buf[400];
    std::snprintf(
        buf, sizeof buf,
        "a knocked sensor: the two traverses of configuration %d differ by a step of "
        "%+.3g +- %.2g um between x = %.4g and %.4g mm (z = %.3g, p = %.2g; the best "
        "other configuration z = %.3g)%s",
        c + 1, out.size_um, out.u_size_um, (out.position - 1) * cfg.dx_mm, out.x_mm, out.z,
        out.p_value, out.rival_z,
        out.attributed ? ": attributed to it" : ": other configurations explain it almost as well");
    out.finding = buf;
  }
  return out;
}

}  // namespace errsep::core
