#include "errsep/core/effect_traverse.hpp"

#include <algorithm>
#include <cstdio>

namespace errsep::core {

std::string TraverseEffect::description() const {
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "S or gamma not repeating between traverses: m_i -> m_i - sum_k c_ik P_k(2x/L-1), "
                "k = %d..%d (h_i = dS_i + O_i*dgamma_i)",
                min_degree_, max_degree_);
  return buf;
}

std::vector<std::string> TraverseEffect::parameter_names() const {
  std::vector<std::string> n;
  for (int i = 1; i <= 4; ++i)
    for (int k = min_degree_; k <= max_degree_; ++k)
      n.push_back("dS" + std::to_string(i) + "_P" + std::to_string(k) + "_um");
  return n;
}

Eigen::MatrixXd TraverseEffect::basis(const FourSensorConfig& cfg) const {
  const int P = cfg.positions(), K = max_degree_;
  const double L = cfg.travel_mm();
  const int k0 = std::max(0, min_degree_);
  Eigen::MatrixXd phi(P, std::max(0, K - k0 + 1));
  for (int n = 0; n < P; ++n) {
    const double u = 2.0 * n * cfg.dx_mm / L - 1.0;
    // Bonnet's recursion: (k + 1)·P_{k+1} = (2k + 1)·u·P_k − k·P_{k−1}, P_0 = 1, P_1 = u.
    double pkm1 = 0.0, pk = 1.0;
    for (int k = 0; k <= K; ++k) {
      if (k >= k0) phi(n, k - k0) = pk;  // P_k
      const double next = ((2.0 * k + 1.0) * u * pk - k * pkm1) / (k + 1.0);
      pkm1 = pk;
      pk = next;
    }
  }
  return phi;
}

Eigen::MatrixXd TraverseEffect::correction_um(const Eigen::VectorXd& p,
                                              const EffectContext& ctx) const {
  const Eigen::MatrixXd phi = basis(ctx.cfg);
  const Eigen::Index nb = phi.cols();
  Eigen::MatrixXd c(phi.rows(), 4);
  for (int i = 0; i < 4; ++i)
    c.col(i) = phi * p.segment(i * nb, nb);
  return c;
}

Eigen::MatrixXd TraverseEffect::jacobian(const Eigen::VectorXd&, const EffectContext& ctx) const {
  const Eigen::MatrixXd phi = basis(ctx.cfg);
  const Eigen::Index P = phi.rows(), nb = phi.cols();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(4 * P, 4 * nb);
  for (Eigen::Index n = 0; n < P; ++n)
    for (int i = 0; i < 4; ++i)
      J.block(4 * n + i, i * nb, 1, nb) = phi.row(n);
  return J;
}

std::unique_ptr<ModelEffect> TraverseEffect::clone() const {
  return std::make_unique<TraverseEffect>(*this);
}

}  // namespace errsep::core
