#include "errsep/core/four_sensor_evaluation.hpp"

#include <vector>

namespace errsep::core {

StraightnessEstimate four_sensor_straightness(const FourSensorResult& r, ReferenceLine reference,
                                              int draws, const EvaluationOptions& opts) {
  const std::vector<double> x(r.x_mm.data(), r.x_mm.data() + r.x_mm.size());
  const std::vector<double> s(r.S_um.data(), r.S_um.data() + r.S_um.size());
  if (!r.covariance) {
    const std::vector<double> u(r.u_S_um.data(), r.u_S_um.data() + r.u_S_um.size());
    StraightnessEstimate out;
    out.zone = evaluate_straightness(x, s, u, reference, opts);
    out.straightness_um = out.zone.straightness_um;
    out.expanded_um = out.zone.uncertainty.expanded;
    out.u_um = out.expanded_um / opts.coverage_factor;
    return out;
  }
  const auto cov = r.covariance;
  return estimate_straightness(
      x, s,
      [cov](const std::vector<double>& c) {
        return cov->variance(
            Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size())), {},
            {});
      },
      [cov](std::uint64_t seed, std::vector<double>& dev) {
        Eigen::VectorXd dS, dg;
        cov->sample(seed, dS, dg);
        dev.assign(dS.data(), dS.data() + dS.size());
      },
      reference, draws, 1, opts);
}

}  // namespace errsep::core
