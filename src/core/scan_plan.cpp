// The scan plan of scan_plan.hpp: the prediction of one configuration and the search.
#include "errsep/core/scan_plan.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include "errsep/core/four_sensor_posterior.hpp"

namespace errsep::core {

ScanPrediction predict_scan(const FourSensorConfig& cfg, double sigma_sample_um, int averages,
                            double coverage_factor) {
  if (averages < 1)
    throw std::invalid_argument("predict_scan: averages = " + std::to_string(averages) +
                                ": need at least one sample per point");
  if (!(std::isfinite(coverage_factor) && coverage_factor > 0.0))
    throw std::invalid_argument("predict_scan: coverage factor " + std::to_string(coverage_factor) +
                                " must be positive");
  ScanPrediction out;
  out.config = cfg;
  out.averages = averages;
  out.sigma_sample_um = sigma_sample_um;
  out.sigma_um = sigma_sample_um / std::sqrt(static_cast<double>(averages));
  out.coverage_factor = coverage_factor;
  const FourSensorPrediction p = predict_four_sensor_uncertainty(cfg, out.sigma_um);
  out.x_mm = p.x_mm;
  out.u_S_um = p.u_S_um;
  // δd = (I − H)δS with H the hat matrix of the line [1, x]:
  // Var δd_i = V_ii − 2·u_iᵀG(XᵀV)_i + u_iᵀG(XᵀVX)G·u_i, u_i = (1, x_i), G = (XᵀX)⁻¹.
  const auto P = static_cast<Eigen::Index>(p.x_mm.size());
  Eigen::MatrixXd X(P, 2);
  X.col(0).setOnes();
  X.col(1) = p.x_mm;
  const Eigen::MatrixXd VX = p.covariance->covariance_S_with(X);  // P × 2
  const Eigen::Matrix2d G = (X.transpose() * X).inverse();
  const Eigen::Matrix2d GXVXG = G * (X.transpose() * VX) * G;
  out.u_deviation_um.resize(P);
  double sum = 0.0;
  for (Eigen::Index i = 0; i < P; ++i) {
    const Eigen::Vector2d u = X.row(i).transpose();
    const double v =
        p.u_S_um(i) * p.u_S_um(i) - 2.0 * u.dot(G * VX.row(i).transpose()) + u.dot(GXVXG * u);
    out.u_deviation_um(i) = std::sqrt(std::max(0.0, v));
    sum += std::max(0.0, v);
  }
  out.u_straightness_um = std::sqrt(2.0 * sum / static_cast<double>(P));
  out.expanded_um = coverage_factor * out.u_straightness_um;
  out.expanded_bound_um = coverage_factor * 2.0 * out.u_deviation_um.maxCoeff();
  return out;
}

bool ScanPlanOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!positive(travel_mm))
    return fail("travel_mm = " + std::to_string(travel_mm) + ": must be a positive length");
  if (dx_mm.empty()) return fail("dx_mm: give at least one sampling interval");
  for (const double dx : dx_mm)
    if (!positive(dx) || dx > travel_mm)
      return fail("dx_mm = " + std::to_string(dx) + ": must be positive and at most the travel " +
                  std::to_string(travel_mm) + " mm");
  if (stage.positions_mm.empty()) {
    if (!positive(stage.range_mm))
      return fail("stage.range_mm = " + std::to_string(stage.range_mm) +
                  ": must be a positive length (or list the stage's positions)");
    if (!(std::isfinite(stage.step_mm) && stage.step_mm >= 0.0))
      return fail("stage.step_mm = " + std::to_string(stage.step_mm) + ": must be >= 0");
  } else {
    if (stage.positions_mm.size() < 4)
      return fail("stage.positions_mm: " + std::to_string(stage.positions_mm.size()) +
                  " positions, the four configurations need at least 4");
    for (const double p : stage.positions_mm)
      if (!std::isfinite(p)) return fail("stage.positions_mm: a position is not finite");
  }
  if (!(std::isfinite(reference_length_max_mm) && reference_length_max_mm >= 0.0))
    return fail("reference_length_max_mm = " + std::to_string(reference_length_max_mm) +
                ": must be >= 0 (0 = no limit)");
  if (reference_length_max_mm > 0.0 && reference_length_max_mm <= travel_mm)
    return fail("reference_length_max_mm = " + std::to_string(reference_length_max_mm) +
                ": the reference must be longer than the travel " + std::to_string(travel_mm) +
                " mm (by the sensor offsets)");
  if (!positive(sigma_um))
    return fail("sigma_um = " + std::to_string(sigma_um) + ": must be a positive noise level");
  if (averages_max < 1)
    return fail("averages_max = " + std::to_string(averages_max) + ": must be >= 1");
  if (!positive(target_U_um))
    return fail("target_U_um = " + std::to_string(target_U_um) + ": must be positive");
  if (!positive(coverage_factor))
    return fail("coverage_factor = " + std::to_string(coverage_factor) + ": must be positive");
  if (max_evaluations < 10)
    return fail("max_evaluations = " + std::to_string(max_evaluations) + ": must be >= 10");
  return true;
}

namespace {

// A candidate before its prediction: offsets a < b < T in samples at one dx.
struct Offsets {
  int a, b, T;
  double origin_mm;
  auto key() const { return std::make_tuple(T, a, b); }
};

// k·dx is a whole number of steps (relative tolerance: positions are given in decimal mm).
bool on_grid(double length_mm, double step_mm) {
  if (step_mm <= 0.0) return true;
  const double r = length_mm / step_mm;
  return std::abs(r - std::round(r)) <= 1e-6 * std::max(1.0, r);
}

// Every admissible configuration at one dx: offsets the stage can reach, coprime, T <= T_max.
std::vector<Offsets> admissible(const SensorStageLimits& st, double dx, int T_max) {
  std::map<std::tuple<int, int, int>, Offsets> found;
  auto add_from = [&](const std::vector<int>& k, double origin) {
    for (std::size_t i = 0; i < k.size(); ++i)
      for (std::size_t j = i + 1; j < k.size(); ++j)
        for (std::size_t l = j + 1; l < k.size(); ++l) {
          const int a = k[i], b = k[j], T = k[l];
          if (std::gcd(std::gcd(a, b), T) != 1) continue;  // FourSensorConfig::is_valid
          found.try_emplace(std::make_tuple(T, a, b), Offsets{a, b, T, origin});
        }
  };
  if (st.positions_mm.empty()) {
    std::vector<int> k;
    const int reach = static_cast<int>(std::floor(st.range_mm / dx * (1.0 + 1e-9)));
    for (int q = 1; q <= std::min(reach, T_max); ++q)
      if (on_grid(q * dx, st.step_mm)) k.push_back(q);
    add_from(k, 0.0);
  } else {
    std::vector<double> pos = st.positions_mm;
    std::sort(pos.begin(), pos.end());
    for (std::size_t i = 0; i < pos.size(); ++i) {
      std::vector<int> k;
      for (std::size_t j = i + 1; j < pos.size(); ++j) {
        const double d = pos[j] - pos[i];
        const double r = d / dx;
        const auto q = static_cast<int>(std::lround(r));
        if (q >= 1 && q <= T_max && std::abs(r - q) <= 1e-6 * std::max(1.0, r) &&
            (k.empty() || k.back() != q))
          k.push_back(q);
      }
      add_from(k, pos[i]);
    }
  }
  std::vector<Offsets> out;
  out.reserve(found.size());
  for (const auto& [key, o] : found)
    out.push_back(o);
  return out;
}

FourSensorConfig config_of(const Offsets& o, double dx, int P) {
  return FourSensorConfig{dx, o.a, o.b - o.a, o.T - o.b, P + o.T};
}

ScanPlanCandidate candidate_of(const FourSensorConfig& cfg, double origin, double U1,
                               const ScanPlanOptions& opts) {
  ScanPlanCandidate c;
  c.config = cfg;
  c.stage_origin_mm = origin;
  c.expanded_one_sample_um = U1;
  const double need = std::ceil((U1 / opts.target_U_um) * (U1 / opts.target_U_um) - 1e-12);
  c.averages = need <= static_cast<double>(opts.averages_max) ? std::max(1, static_cast<int>(need))
                                                              : opts.averages_max;
  c.expanded_um = U1 / std::sqrt(static_cast<double>(c.averages));
  c.readings = 4LL * cfg.positions() * c.averages;
  return c;
}

// Fewest readings among those that reach the target, then the lowest U; those that cannot
// reach it after all that can, by U.
bool better(const ScanPlanCandidate& x, const ScanPlanCandidate& y, double target) {
  const bool mx = x.expanded_um <= target * (1.0 + 1e-12),
             my = y.expanded_um <= target * (1.0 + 1e-12);
  if (mx != my) return mx;
  if (mx && x.readings != y.readings) return x.readings < y.readings;
  return x.expanded_um < y.expanded_um;
}

// Predictions at one dx, by offsets; the search itself.
class DxSearch {
 public:
  DxSearch(const ScanPlanOptions& o, double dx, int P, std::vector<Offsets> cand)
      : o_(o), dx_(dx), P_(P), cand_(std::move(cand)) {
    for (std::size_t i = 0; i < cand_.size(); ++i)
      index_[cand_[i].key()] = i;
  }
  std::size_t size() const { return cand_.size(); }
  long long evaluated() const { return static_cast<long long>(U1_.size()); }

  void all() {
    for (std::size_t i = 0; i < cand_.size(); ++i)
      eval(i);
  }

  // An evenly spread sample (every stride-th in (T, a, b) order), then a pattern search in
  // (a, b, T) from the best few, steps halving to one sample, until `budget` predictions.
  void sampled(long long budget) {
    const long long sample = std::max<long long>(1, budget / 2);
    const double stride = static_cast<double>(cand_.size()) / static_cast<double>(sample);
    for (long long s = 0; s < sample; ++s)
      eval(static_cast<std::size_t>(std::floor(static_cast<double>(s) * stride)));
    std::vector<std::pair<double, std::size_t>> best;
    for (const auto& [i, U] : U1_)
      best.emplace_back(U, i);
    std::sort(best.begin(), best.end());
    const int T_span = cand_.back().T;
    for (std::size_t start = 0; start < std::min<std::size_t>(4, best.size()); ++start) {
      std::size_t at = best[start].second;
      int h = std::max(1, static_cast<int>(std::ceil(stride)));
      h = std::min(h, std::max(1, T_span / 4));
      while (h >= 1 && evaluated() < budget) {
        const Offsets c = cand_[at];
        std::size_t next = at;
        const int moves[8][3] = {{h, 0, 0}, {-h, 0, 0}, {0, h, 0}, {0, -h, 0},
                                 {0, 0, h}, {0, 0, -h}, {h, h, h}, {-h, -h, -h}};
        for (const auto& m : moves) {
          const auto it = index_.find(std::make_tuple(c.T + m[2], c.a + m[0], c.b + m[1]));
          if (it == index_.end() || evaluated() >= budget) continue;
          if (eval(it->second) < U1_.at(next)) next = it->second;
        }
        if (next == at)
          h /= 2;
        else
          at = next;
      }
    }
  }

  void collect(std::vector<ScanPlanCandidate>& out) const {
    for (const auto& [i, U] : U1_)
      out.push_back(candidate_of(config_of(cand_[i], dx_, P_), cand_[i].origin_mm, U, o_));
  }

 private:
  double eval(std::size_t i) {
    if (const auto it = U1_.find(i); it != U1_.end()) return it->second;
    const double U =
        predict_scan(config_of(cand_[i], dx_, P_), o_.sigma_um, 1, o_.coverage_factor).expanded_um;
    U1_[i] = U;
    return U;
  }
  const ScanPlanOptions& o_;
  double dx_;
  int P_;
  std::vector<Offsets> cand_;
  std::map<std::tuple<int, int, int>, std::size_t> index_;
  std::map<std::size_t, double> U1_;
};

// The paper's spacings (1, 1, 5) at the same travel, dx and K; empty (no positions) when the
// travel is too short for them.
ScanPrediction baseline_of(const FourSensorConfig& c, double sigma_um, int averages, double k,
                           std::vector<std::string>& notes) {
  const FourSensorConfig b{c.dx_mm, 1, 1, 5, c.positions() + 7};
  if (!b.is_valid()) {
    notes.push_back("no (1, 1, 5) comparison: the travel is too short for it");
    return {};
  }
  return predict_scan(b, sigma_um, averages, k);
}

std::string fmt(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

}  // namespace

ScanPlan plan_four_sensor_scan(const ScanPlanOptions& opts) {
  std::string why;
  if (!opts.is_valid(&why)) throw std::invalid_argument("scan plan: " + why);
  ScanPlan plan;
  plan.target_U_um = opts.target_U_um;
  std::vector<DxSearch> searches;
  std::vector<std::string> skipped;
  for (const double dx : opts.dx_mm) {
    const double steps = opts.travel_mm / dx;
    if (std::abs(steps - std::round(steps)) > 1e-6 * steps) {
      skipped.push_back("dx " + fmt(dx) + " mm: the travel " + fmt(opts.travel_mm) +
                        " mm is not a whole number of steps");
      continue;
    }
    const int P = static_cast<int>(std::lround(steps)) + 1;
    int T_max = P - 5;  // N = P + T >= 2T + 5
    if (opts.reference_length_max_mm > 0.0)
      T_max = std::min(T_max, static_cast<int>(std::floor(
                                  (opts.reference_length_max_mm - opts.travel_mm) / dx + 1e-9)));
    std::vector<Offsets> cand = admissible(opts.stage, dx, T_max);
    if (cand.empty()) {
      skipped.push_back("dx " + fmt(dx) +
                        " mm: no three coprime offsets the stage can reach (a multiple of dx and "
                        "of the stage step, within the stage and reference limits)");
      continue;
    }
    plan.candidates += static_cast<long long>(cand.size());
    searches.emplace_back(opts, dx, P, std::move(cand));
  }
  if (searches.empty()) {
    std::string msg = "scan plan: no admissible configuration";
    for (const auto& s : skipped)
      msg += "; " + s;
    throw std::invalid_argument(msg);
  }
  plan.notes = skipped;
  plan.exhaustive = plan.candidates <= opts.max_evaluations;
  for (auto& s : searches) {
    if (plan.exhaustive) {
      s.all();
    } else {
      // The budget shared in proportion to each dx's candidates.
      const auto share = static_cast<long long>(
          std::ceil(static_cast<double>(opts.max_evaluations) * static_cast<double>(s.size()) /
                    static_cast<double>(plan.candidates)));
      s.sampled(std::max<long long>(10, share));
    }
    plan.evaluated += s.evaluated();
  }
  plan.notes.push_back(plan.exhaustive
                           ? "search: every one of " + std::to_string(plan.candidates) +
                                 " admissible configurations predicted"
                           : "search: " + std::to_string(plan.evaluated) + " of " +
                                 std::to_string(plan.candidates) +
                                 " admissible configurations predicted (an even sample, then a "
                                 "pattern search around the best; raise max_evaluations to "
                                 "predict all)");
  std::vector<ScanPlanCandidate> all;
  for (const auto& s : searches)
    s.collect(all);
  std::sort(all.begin(), all.end(),
            [&](const auto& x, const auto& y) { return better(x, y, opts.target_U_um); });
  plan.chosen = all.front();
  plan.target_met = plan.chosen.expanded_um <= opts.target_U_um * (1.0 + 1e-12);
  for (std::size_t i = 1; i < all.size() && plan.runners_up.size() < 5; ++i)
    plan.runners_up.push_back(all[i]);
  plan.prediction =
      predict_scan(plan.chosen.config, opts.sigma_um, plan.chosen.averages, opts.coverage_factor);
  plan.baseline = baseline_of(plan.chosen.config, opts.sigma_um, plan.chosen.averages,
                              opts.coverage_factor, plan.notes);
  return plan;
}

ScanPlan evaluate_scan_configuration(const FourSensorConfig& cfg, double sigma_um, int averages,
                                     double target_U_um, double coverage_factor) {
  ScanPlan plan;
  plan.target_U_um = target_U_um;
  plan.prediction = predict_scan(cfg, sigma_um, averages, coverage_factor);
  plan.chosen.config = cfg;
  plan.chosen.averages = averages;
  plan.chosen.expanded_um = plan.prediction.expanded_um;
  plan.chosen.expanded_one_sample_um =
      plan.prediction.expanded_um * std::sqrt(static_cast<double>(averages));
  plan.chosen.readings = plan.prediction.readings();
  plan.target_met = target_U_um <= 0.0 || plan.chosen.expanded_um <= target_U_um;
  plan.candidates = plan.evaluated = 1;
  plan.notes.push_back("the given configuration, no search");
  plan.baseline = baseline_of(cfg, sigma_um, averages, coverage_factor, plan.notes);
  return plan;
}

}  // namespace errsep::core
