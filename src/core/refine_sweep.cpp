#include "errsep/core/refine_sweep.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <vector>

#include "errsep/core/four_sensor_sequence_simulation.hpp"
#include "errsep/core/four_sensor_simulation.hpp"

namespace errsep::core {

namespace {

double rms(const Eigen::VectorXd& v) {
  return v.size() ? std::sqrt(v.squaredNorm() / static_cast<double>(v.size())) : 0.0;
}

// γ's points within 2u_γ, the error about its constant and line (what one scan cannot see, as
// the errors gamma_*_urad).
int covered_gamma_within_2u(const Eigen::VectorXd& gamma_rad, const Eigen::VectorXd& truth_rad,
                            const Eigen::VectorXd& u_rad) {
  const Eigen::VectorXd dev = remove_polynomial(gamma_rad - truth_rad, 1);
  return static_cast<int>((dev.array().abs() <= 2.0 * u_rad.array()).count());
}

}  // namespace

SweepRun evaluate_refine_run(UndeclaredEffect effect, const UndeclaredCaseOptions& cases,
                             const RefineOptions& refine) {
  const UndeclaredCase c = simulate_undeclared(effect, cases);
  const RefineTruth truth{c.f_um, c.S_um, c.gamma_rad};
  SweepRun run;
  run.seed = cases.seed;
  run.description = c.description;
  const RefineResult r = refine_four_sensor(c.cfg, c.m_um, c.t_s, refine);
  const FourSensorResult clean = separate_four_sensor(c.cfg, c.m_clean_um, refine.solve);
  const ProfileErrors ec = profile_errors(clean, truth), eb = profile_errors(r.before, truth),
                      ea = profile_errors(r.after, truth);
  run.model = r.model_name;
  run.S_clean_um = ec.S_um;
  run.S_before_um = eb.S_um;
  run.S_after_um = ea.S_um;
  run.gamma_clean_urad = ec.gamma_urad;
  run.gamma_before_urad = eb.gamma_urad;
  run.gamma_after_urad = ea.gamma_urad;
  run.u_S_after_um = rms(r.after.u_S_um);
  run.u_S_before_um = rms(r.before.u_S_um);
  run.u_gamma_after_urad = 1e6 * rms(r.after.u_gamma_rad);
  run.added = !r.effects.empty();
  const std::string lib = library_effect_name(effect);
  for (const auto& e : r.effects)
    run.identified = run.identified || (!lib.empty() && e->name() == lib);
  for (bool a : r.applied)
    run.applied = run.applied || a;
  run.not_white = !r.model_complete();
  run.unbounded = !r.unbounded.empty();
  if (!lib.empty())
    for (const auto& e : default_effect_library())
      if (e->name() == lib) {
        const EffectIdentifiability id = effect_identifiability(c.cfg, c.m_um, c.t_s, *e, refine);
        run.identifiable_from_plan = id.identifiable;
        run.identifiability = id.brief();
      }
  for (const auto& v : r.verdicts)
    run.verdicts += (run.verdicts.empty() ? "" : " | ") + v;
  // What the analyses after the loop did (they too change S): gross errors, a non-linearity.
  for (const auto& f : r.gross.findings)
    run.verdicts += (run.verdicts.empty() ? "" : " | ") + f;
  if (r.nonlinearity.detected)
    run.verdicts += (run.verdicts.empty() ? "" : " | ") + r.nonlinearity.finding;
  for (const auto& v : r.verdicts)
    run.not_identifiable_reported =
        run.not_identifiable_reported || v.find("not identifiable from this plan") != v.npos;
  // The gauge: what a step changed of S's constant, line and bow.
  {
    const Eigen::VectorXd d = r.after.S_um - r.before.S_um;
    run.gauge_change_um = rms(d - remove_polynomial(d, 2));
  }
  // Coverage, pointwise and of the shape.
  const Eigen::VectorXd dS = r.after.S_um - c.S_um;
  run.points = static_cast<int>(dS.size());
  for (Eigen::Index n = 0; n < dS.size(); ++n)
    if (std::abs(dS(n)) <= 2.0 * r.after.u_S_um(n)) ++run.covered;
  run.covered_gamma = covered_gamma_within_2u(r.after.gamma_rad, c.gamma_rad, r.after.u_gamma_rad);
  if (r.after.covariance) {
    std::vector<int> all(static_cast<std::size_t>(dS.size()));
    for (std::size_t n = 0; n < all.size(); ++n)
      all[n] = static_cast<int>(n);
    const Eigen::MatrixXd V = r.after.covariance->covariance_S(all);
    const Eigen::MatrixXd Vs = remove_polynomial(remove_polynomial(V, 2).transpose(), 2);
    const Eigen::VectorXd ds = remove_polynomial(dS, 2);
    for (Eigen::Index n = 0; n < ds.size(); ++n)
      if (std::abs(ds(n)) <= 2.0 * std::sqrt(std::max(0.0, Vs(n, n)))) ++run.covered_shape;
  }
  return run;
}

double SweepCell::fraction(bool (*pred)(const SweepRun&)) const {
  if (runs.empty()) return 0.0;
  return static_cast<double>(std::count_if(runs.begin(), runs.end(), pred)) /
         static_cast<double>(runs.size());
}

double SweepCell::median(double (*get)(const SweepRun&)) const {
  std::vector<double> v;
  for (const auto& r : runs)
    v.push_back(get(r));
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

double SweepCell::worst(double (*get)(const SweepRun&)) const {
  double w = 0.0;
  for (const auto& r : runs)
    w = std::max(w, get(r));
  return w;
}

int SweepCell::count(bool (*pred)(const SweepRun&)) const {
  return static_cast<int>(std::count_if(runs.begin(), runs.end(), pred));
}

double SweepCell::coverage() const {
  long in = 0, all = 0;
  for (const auto& r : runs)
    in += r.covered, all += r.points;
  return all ? static_cast<double>(in) / static_cast<double>(all) : 0.0;
}

double SweepCell::coverage_gamma() const {
  long in = 0, all = 0;
  for (const auto& r : runs)
    in += r.covered_gamma, all += r.points;
  return all ? static_cast<double>(in) / static_cast<double>(all) : 0.0;
}

double SweepCell::coverage_shape() const {
  long in = 0, all = 0;
  for (const auto& r : runs)
    in += r.covered_shape, all += r.points;
  return all ? static_cast<double>(in) / static_cast<double>(all) : 0.0;
}

double SweepCell::coverage_where(bool (*pred)(const SweepRun&), int* runs_counted) const {
  long in = 0, all = 0;
  int n = 0;
  for (const auto& r : runs)
    if (pred(r)) {
      ++n;
      in += r.covered;
      all += r.points;
    }
  if (runs_counted) *runs_counted = n;
  return all ? static_cast<double>(in) / static_cast<double>(all) : -1.0;
}

std::string coverage_breakdown(const SweepCell& c) {
  int na = 0, nd = 0, nn = 0;
  const double ca = c.coverage_where([](const SweepRun& r) { return r.applied; }, &na);
  const double cd = c.coverage_where([](const SweepRun& r) { return r.added && !r.applied; }, &nd);
  const double cn = c.coverage_where([](const SweepRun& r) { return !r.added; }, &nn);
  std::vector<double> ratio;
  for (const auto& r : c.runs)
    if (r.u_S_before_um > 0 && r.u_S_after_um > 1.01 * r.u_S_before_um)
      ratio.push_back(r.u_S_after_um / r.u_S_before_um);
  std::sort(ratio.begin(), ratio.end());
  int unbounded = 0;
  double bounded_max = 0.0;  // u_S / max(S error, raw u_S) of the runs not called unbounded
  for (const auto& r : c.runs) {
    if (r.unbounded)
      ++unbounded;
    else if (const double m = std::max(r.S_after_um, r.u_S_before_um); m > 0)
      bounded_max = std::max(bounded_max, r.u_S_after_um / m);
  }
  char buf[640];
  std::snprintf(
      buf, sizeof buf,
      "%-12s %-12s %5.2f coverage within 2 u_S: %.3f; applied %.3f (%d runs), detected not "
      "applied %.3f (%d), nothing added %.3f (%d); u_S widened in %zu (median x%.2f, "
      "max x%.2f); unbounded in %d, others u_S <= x%.2f max(S error, raw u_S)",
      to_string(c.effect), to_string(c.plan), c.sigma_um, c.coverage(), ca, na, cd, nd, cn, nn,
      ratio.size(), ratio.empty() ? 1.0 : ratio[ratio.size() / 2],
      ratio.empty() ? 1.0 : ratio.back(), unbounded, bounded_max);
  return buf;
}

SweepCell run_sweep_cell(UndeclaredEffect effect, double sigma_um, int seeds, std::uint64_t seed0,
                         const RefineOptions& refine, const UndeclaredCaseOptions& base) {
  SweepCell cell;
  cell.effect = effect;
  cell.sigma_um = sigma_um;
  for (int k = 0; k < seeds; ++k) {
    UndeclaredCaseOptions o = base;
    o.sigma_um = sigma_um;
    o.seed = seed0 + static_cast<std::uint64_t>(k);
    cell.runs.push_back(evaluate_refine_run(effect, o, refine));
  }
  return cell;
}

bool sequence_simulates(UndeclaredEffect effect) {
  switch (effect) {
    case UndeclaredEffect::pe1:
    case UndeclaredEffect::gain:
    case UndeclaredEffect::pe2:
    case UndeclaredEffect::periodic:
      return false;
    default:
      return true;
  }
}

namespace {

// The sequence refine's effect that describes an injected one (drift and thermal are one
// family, sequence_refine.hpp); false for the others.
bool sequence_kind_of(UndeclaredEffect e, SequenceEffectKind* k) {
  switch (e) {
    case UndeclaredEffect::drift_one:
    case UndeclaredEffect::drift_all:
      *k = SequenceEffectKind::drift;
      return true;
    case UndeclaredEffect::thermal_one:
    case UndeclaredEffect::thermal_all:
      *k = SequenceEffectKind::thermal;
      return true;
    case UndeclaredEffect::traverse:
      *k = SequenceEffectKind::traverse;
      return true;
    default:
      return false;
  }
}

bool drift_family(SequenceEffectKind k) {
  return k == SequenceEffectKind::drift || k == SequenceEffectKind::thermal;
}

}  // namespace

PlanChoice identifying_plan(UndeclaredEffect effect, const FourSensorConfig& cfg,
                            const SequenceRefineOptions& seq_opts) {
  PlanChoice c;
  c.effect = effect;
  c.plan = ScanSequenceKind::single;
  SequenceEffectKind kind{};
  char buf[512];
  if (sequence_kind_of(effect, &kind)) {
    // Every redundant plan's identifiability of the effect (of both drift members for drift:
    // the refine takes whichever fits, so both must be identifiable), the smallest
    // undetermined S gain winning (for the drift family the larger of the drift's and its
    // form's: sequence_refine.hpp SequenceIdentifiability::form_undetermined_S_gain).
    double best = 0;
    int best_T = 0;
    bool found = false;
    std::string scores;
    for (const ScanSequenceKind k : all_scan_sequence_kinds()) {
      const ScanSequence seq = ScanSequence::make(k, cfg);
      if (!seq.redundant()) continue;
      bool ok = true;
      double gain = 0;
      for (const auto& id : sequence_identifiability(cfg, seq, seq_opts))
        if (id.kind == kind || (drift_family(kind) && drift_family(id.kind))) {
          // The drift family's form ranks the plans too (the refine takes a warm-up or a line,
          // whichever fits, and takes S midway where it cannot tell them): among the plans that
          // identify the drift, the one that best determines its form wins.
          ok = ok && id.identifiable_from_plan;
          gain = std::max({gain, id.undetermined_S_gain, id.form_undetermined_S_gain});
        }
      std::snprintf(buf, sizeof buf, "%s%s %.2g%s", scores.empty() ? "" : ", ", to_string(k), gain,
                    ok ? "" : " (no)");
      scores += buf;
      if (ok && (!found || gain < best - 1e-9 || (gain <= best + 1e-9 && seq.size() < best_T))) {
        found = true;
        best = gain;
        best_T = seq.size();
        c.plan = k;
      }
    }
    std::snprintf(buf, sizeof buf,
                  "sequence_identifiability of %s%s, undetermined S gain per plan (<= %.2g "
                  "identifiable): %s",
                  to_string(kind), drift_family(kind) ? " and its family, the form's included" : "",
                  seq_opts.undetermined_S_max, scores.c_str());
    c.why = found ? buf : std::string(buf) + "; identifiable from none: single";
    return c;
  }
  switch (effect) {
    case UndeclaredEffect::hysteresis:
      // SequenceHysteresis is identifiable on any plan that reads a configuration both ways.
      // The reversed plan reads every configuration both ways and averages the lag out of S
      // (nothing to correct: the effect never doubles the error there); the serpentine reads
      // configurations 2 and 4 one way only, so the lag biases S and h, determined by
      // configuration 1's two directions, is what corrects it: the plan that shows the loop.
      c.plan = ScanSequenceKind::serpentine;
      c.why =
          "SequenceHysteresis needs a configuration read both ways; serpentine (reversed "
          "averages the lag out of S: nothing to correct)";
      return c;
    case UndeclaredEffect::nonlinearity: {
      // SequenceNonlinearity is identifiable exactly on a plan that re-zeroes the sensor.
      for (const ScanSequenceKind k : all_scan_sequence_kinds())
        if (ScanSequence::make(k, cfg).rezeroed()) {
          c.plan = k;
          break;
        }
      c.why =
          "the sequence refine fits a non-linearity's c2 where the plan re-zeroes the sensor "
          "(SequenceNonlinearity::identifiable)";
      return c;
    }
    case UndeclaredEffect::bump:
      c.why =
          "in neither library and identifiable from no plan: single (the single refine's gross "
          "errors and trace report it)";
      return c;
    case UndeclaredEffect::none:
      c.why = "clean";
      return c;
    default:
      c.why =
          "a single-scan library effect: the sequence refine has no candidate for it, "
          "effect_identifiability judges each single scan";
      return c;
  }
}

std::vector<PlanChoice> sweep_plan_cells(const std::string& plan,
                                         const std::vector<UndeclaredEffect>& effects,
                                         std::vector<std::string>* skipped,
                                         const FourSensorConfig& cfg) {
  std::vector<PlanChoice> cells;
  if (plan == "identifying") {
    std::vector<ScanSequenceKind> used;
    bool clean = false;
    for (const auto e : effects) {
      if (e == UndeclaredEffect::none) {
        clean = true;
        continue;
      }
      cells.push_back(identifying_plan(e, cfg));
      if (std::find(used.begin(), used.end(), cells.back().plan) == used.end())
        used.push_back(cells.back().plan);
    }
    if (clean) {
      if (used.empty()) used.push_back(ScanSequenceKind::single);
      std::vector<PlanChoice> c0;
      for (const auto k : used)
        c0.push_back({UndeclaredEffect::none, k, "clean, on every plan the effects use"});
      cells.insert(cells.begin(), c0.begin(), c0.end());
    }
    return cells;
  }
  const ScanSequenceKind k = scan_sequence_kind_from_string(plan);
  for (const auto e : effects) {
    if (k != ScanSequenceKind::single && !sequence_simulates(e)) {
      if (skipped)
        skipped->push_back(std::string(to_string(e)) + ": not on the " + to_string(k) +
                           " plan (a single-scan library effect: the sequence simulator does not "
                           "model it and the sequence refine has no candidate for it)");
      continue;
    }
    cells.push_back({e, k, "--plan"});
  }
  return cells;
}

SweepRun evaluate_sequence_run(UndeclaredEffect effect, const ScanSequence& seq,
                               const UndeclaredCaseOptions& o, SequenceModel& model) {
  if (!sequence_simulates(effect))
    throw std::invalid_argument(std::string("evaluate_sequence_run: ") + to_string(effect) +
                                " is not simulated on a scan sequence");
  const FourSensorConfig& cfg = o.cfg;
  const double L = cfg.travel_mm();
  const SlidewayTruth truth = random_smooth_truth(cfg, o.seed, o.truth);
  UndeclaredEffectDraws draw(o.seed);
  const double k = o.size;
  SequenceSimOptions so;
  so.sigma_um = o.sigma_um;
  so.seed = undeclared_noise_seed(o.seed);
  SequenceEffects& fx = so.effects;
  char buf[300];
  std::string description = "clean";
  const int which = draw.pick(0, 3);
  switch (effect) {
    case UndeclaredEffect::drift_one:
    case UndeclaredEffect::drift_all:
      for (int c = 0; c < 4; ++c)
        if (effect == UndeclaredEffect::drift_all || c == which)
          fx.drift_um_per_s[static_cast<std::size_t>(c)] = k * draw.sign() * draw.uni(0.01, 0.03);
      std::snprintf(buf, sizeof buf, "drift %+.3g %+.3g %+.3g %+.3g um/s", fx.drift_um_per_s[0],
                    fx.drift_um_per_s[1], fx.drift_um_per_s[2], fx.drift_um_per_s[3]);
      description = buf;
      break;
    case UndeclaredEffect::thermal_one:
    case UndeclaredEffect::thermal_all:
      for (int c = 0; c < 4; ++c)
        if (effect == UndeclaredEffect::thermal_all || c == which)
          fx.thermal_um[static_cast<std::size_t>(c)] = k * draw.sign() * draw.uni(2.0, 5.0);
      fx.thermal_tau_s = draw.uni(20.0, 80.0);
      std::snprintf(buf, sizeof buf, "thermal %+.3g %+.3g %+.3g %+.3g um, tau %.3g s",
                    fx.thermal_um[0], fx.thermal_um[1], fx.thermal_um[2], fx.thermal_um[3],
                    fx.thermal_tau_s);
      description = buf;
      break;
    case UndeclaredEffect::traverse: {
      // The slide bending more on each traverse: P2 and P3 of 1-2 um each at the last traverse,
      // in proportion to the traverse's mid-time (the truth is the first traverse's S).
      const double a2 = k * draw.sign() * draw.uni(1.0, 2.0),
                   a3 = k * draw.sign() * draw.uni(1.0, 2.0);
      const Eigen::VectorXd mid = seq.times_s(cfg).colwise().mean().transpose();
      const double span = std::max(mid.maxCoeff() - mid(0), 1e-9);
      fx.S_change_um = [a2, a3, L, mid, span](int t, double x) {
        const double u = 2.0 * x / L - 1.0;
        return (mid(t) - mid(0)) / span *
               (a2 * 0.5 * (3 * u * u - 1) + a3 * 0.5 * (5 * u * u * u - 3 * u));
      };
      std::snprintf(buf, sizeof buf, "S bending progressively: P2 %.3g um, P3 %.3g um at the end",
                    a2, a3);
      description = buf;
      break;
    }
    case UndeclaredEffect::bump: {
      const int t0 = draw.pick(0, seq.size() - 1);
      const double h = k * draw.sign() * draw.uni(1.5, 3.0), w = draw.uni(5.0, 15.0),
                   x0 = draw.uni(0.1 * L, 0.9 * L);
      fx.S_change_um = [t0, h, w, x0](int t, double x) {
        return t == t0 ? h * std::exp(-0.5 * std::pow((x - x0) / w, 2)) : 0.0;
      };
      std::snprintf(buf, sizeof buf, "bump on traverse %d: %.3g um, %.3g mm wide at %.4g mm",
                    t0 + 1, h, w, x0);
      description = buf;
      break;
    }
    case UndeclaredEffect::hysteresis:
      fx.hysteresis_um = k * hysteresis_size_um(draw);
      std::snprintf(buf, sizeof buf, "sensor hysteresis %.3g um", fx.hysteresis_um);
      description = buf;
      break;
    case UndeclaredEffect::nonlinearity: {
      // As simulate_undeclared: relative to the noise-free readings' range (all traverses, the
      // re-zeroed ones included), q of the half range at its ends.
      SequenceSimOptions s0 = so;
      s0.sigma_um = 0;
      const Eigen::MatrixXd r = simulate_four_sensor_sequence(cfg, truth, seq, s0).m_um;
      const double lo = r.minCoeff(), hi = r.maxCoeff();
      const double half = std::max(0.5 * (hi - lo), 1e-9);
      const double q = k * draw.sign() * draw.uni(0.02, 0.04);
      fx.nonlinearity_c2_per_um = q / half;
      fx.nonlinearity_mid_um = 0.5 * (lo + hi);
      std::snprintf(buf, sizeof buf,
                    "sensor non-linearity: %+.3g %% of the half range %.3g um at its ends", 100 * q,
                    half);
      description = buf;
      break;
    }
    default:
      break;
  }
  const SequenceSimData d = simulate_four_sensor_sequence(cfg, truth, seq, so);
  const SequenceRefineResult r = model.refine(d.m_um);
  const SequenceFit clean = model.fit(d.m_clean_um);
  SweepRun run;
  run.seed = o.seed;
  run.description = description;
  // Errors as profile_errors: S after its constant, line and bow, γ after its constant and line.
  auto s_err = [&](const Eigen::VectorXd& S) { return rms(remove_polynomial(S - d.S_um, 2)); };
  auto g_err = [&](const Eigen::VectorXd& g) {
    return 1e6 * rms(remove_polynomial(g - d.gamma_rad, 1));
  };
  run.S_clean_um = s_err(clean.S_um);
  run.S_before_um = s_err(r.before.S_um);
  run.S_after_um = s_err(r.after.S_um);
  run.gamma_clean_urad = g_err(clean.gamma_rad);
  run.gamma_before_urad = g_err(r.before.gamma_rad);
  run.gamma_after_urad = g_err(r.after.gamma_rad);
  run.u_S_after_um = rms(r.after.u_S_um);
  run.u_S_before_um = rms(r.before.u_S_um);
  run.u_gamma_after_urad = 1e6 * rms(r.after.u_gamma_rad);
  for (const auto& a : r.added)
    run.model += std::string(run.model.empty() ? "" : "+") + to_string(a.kind);
  if (r.knock.fitted) run.model += std::string(run.model.empty() ? "" : "+") + "knock";
  if (r.nonlinearity.applied)
    run.model += std::string(run.model.empty() ? "" : "+") + "nonlinearity";
  if (r.hysteresis.applied) run.model += std::string(run.model.empty() ? "" : "+") + "hysteresis";
  if (run.model.empty()) run.model = "base";
  run.added = !r.added.empty() || r.knock.fitted || r.nonlinearity.applied || r.hysteresis.applied;
  run.applied =
      !r.added.empty() || r.knock.applied || r.nonlinearity.applied || r.hysteresis.applied;
  SequenceEffectKind kind{};
  if (sequence_kind_of(effect, &kind)) {
    for (const auto& a : r.added)
      run.identified =
          run.identified || a.kind == kind || (drift_family(kind) && drift_family(a.kind));
    run.identifiable_from_plan = r.identifiable_from_plan(kind);
    for (const auto& id : r.plan_identifiability)
      if (id.kind == kind) {
        std::snprintf(buf, sizeof buf, "%s on %s: %d of %d directions, undetermined S gain %.2g%s",
                      to_string(kind), r.plan.c_str(), id.identifiable, id.parameters,
                      id.undetermined_S_gain,
                      id.identifiable_from_plan ? "" : " (not identifiable)");
        run.identifiability = buf;
      }
  } else if (effect == UndeclaredEffect::hysteresis) {
    run.identified = r.hysteresis.detected;
    run.identifiable_from_plan = r.hysteresis.identifiable;
    run.identifiability = r.hysteresis.identifiable
                              ? "hysteresis: the plan reads a configuration both ways"
                              : "hysteresis: the plan reads every configuration one way";
  } else if (effect == UndeclaredEffect::nonlinearity) {
    run.identified = r.nonlinearity.detected;
    run.identifiable_from_plan = r.nonlinearity.identifiable;
    run.identifiability = r.nonlinearity.identifiable ? "nonlinearity: the plan re-zeroes"
                                                      : "nonlinearity: the plan does not re-zero";
  }
  // Not white: the refine says the readings hold something its model lacks (the trace of the
  // final fit depends on a recorded variable, a non-linearity or a knock found).
  run.not_white = r.trace.depends || r.nonlinearity.detected || r.knock.scan.found;
  run.unbounded = !r.unbounded.empty();
  for (const auto& line : r.report) {
    run.verdicts += (run.verdicts.empty() ? "" : " | ") + line;
    run.not_identifiable_reported =
        run.not_identifiable_reported || line.find("not identifiable from this plan") != line.npos;
  }
  {
    const Eigen::VectorXd dS = r.after.S_um - r.before.S_um;
    run.gauge_change_um = rms(dS - remove_polynomial(dS, 2));
  }
  // Coverage: the sequence fit's u_S is of Ŝ about its best-fit constant, line and bow, so the
  // error is taken likewise (pointwise and shape are the same here).
  const Eigen::VectorXd dev = remove_polynomial(r.after.S_um - d.S_um, 2);
  run.points = static_cast<int>(dev.size());
  for (Eigen::Index n = 0; n < dev.size(); ++n)
    if (std::abs(dev(n)) <= 2.0 * r.after.u_S_um(n)) ++run.covered;
  run.covered_shape = run.covered;
  run.covered_gamma = covered_gamma_within_2u(r.after.gamma_rad, d.gamma_rad, r.after.u_gamma_rad);
  return run;
}

SweepCell run_sweep_cell_on(ScanSequenceKind plan, UndeclaredEffect effect, double sigma_um,
                            int seeds, std::uint64_t seed0, const RefineOptions& refine,
                            const UndeclaredCaseOptions& base,
                            const SequenceRefineOptions& seq_opts) {
  if (plan == ScanSequenceKind::single)
    return run_sweep_cell(effect, sigma_um, seeds, seed0, refine, base);
  SweepCell cell;
  cell.effect = effect;
  cell.sigma_um = sigma_um;
  cell.plan = plan;
  const ScanSequence seq = ScanSequence::make(plan, base.cfg, base.speed_mm_per_s);
  SequenceModel model(base.cfg, seq, seq_opts);
  for (int k = 0; k < seeds; ++k) {
    UndeclaredCaseOptions o = base;
    o.sigma_um = sigma_um;
    o.seed = seed0 + static_cast<std::uint64_t>(k);
    cell.runs.push_back(evaluate_sequence_run(effect, seq, o, model));
  }
  return cell;
}

MustShow must_show(const std::vector<SweepCell>& cells) {
  MustShow m;
  for (const auto& c : cells) {
    const bool library = in_refine_library(c.effect, c.plan == ScanSequenceKind::single);
    for (const auto& r : c.runs) {
      m.points += r.points;
      m.covered += r.covered;
      m.covered_gamma += r.covered_gamma;
      if (r.added) m.points_found += r.points, m.covered_found += r.covered;
      if (c.effect == UndeclaredEffect::none) {
        ++m.clean_runs;
        m.clean_added += r.added;
      } else if (library) {
        ++m.library_runs;
        m.library_worse_beyond_u += r.worse_beyond_u();
        if (r.identifiable_from_plan) {
          ++m.library_identifiable;
          m.library_halved += r.halved();
          if (r.doubled()) {
            ++m.library_identifiable_doubled;
            m.library_halved_doubled += r.halved();
            m.library_halved_where_doubled += r.halved_where_doubled();
          }
        }
      } else {
        ++m.not_in_library_runs;
        m.not_in_library_not_white += r.not_white;
      }
    }
  }
  return m;
}

std::string MustShow::brief() const {
  char buf[1100];
  std::snprintf(buf, sizeof buf,
                "clean: added in %d of %d runs; library effects: worse beyond u in %d of %d, "
                "halved in %d of the %d identifiable from the plan (%d of the %d where the effect "
                "doubled the clean S error; S halved and gamma too where the effect doubled "
                "gamma's in %d); not in the library: not white "
                "in %d of %d; u_S coverage (2 u_S) %ld of %ld points (%.3f), %.3f where something "
                "was added (%ld points); u_gamma coverage (2 u_gamma, gamma about its constant and "
                "line) %.3f",
                clean_added, clean_runs, library_worse_beyond_u, library_runs, library_halved,
                library_identifiable, library_halved_doubled, library_identifiable_doubled,
                library_halved_where_doubled, not_in_library_not_white, not_in_library_runs,
                covered, points, coverage(),
                points_found ? static_cast<double>(covered_found) / points_found : 0.0,
                points_found, coverage_gamma());
  return buf;
}

std::string sweep_header() {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "%-12s %-12s %5s %4s | %5s %5s %5s %5s %5s | %6s %6s %6s %6s %6s | %6s %6s %6s "
                "%6s | %5s %5s %5s | %5s %5s %5s | %7s %7s %7s %7s",
                "effect", "plan", "sigma", "runs", "added", "ident", "appl", "!wht", "!idp",
                "S_cln", "S_bef", "S_aft", "Sbef^", "Saft^", "g_bef", "g_aft", "gbef^", "gaft^",
                "worse", ">u", "half", "cov", "covsh", "covg", "hlf/idf", "idf/dbl", "hlf/i+d",
                "hwd/i+d");
  return std::string(buf) +
         "\n  (fractions of runs; errors RMS in um / urad, median and ^ worst; S_cln: the same "
         "scan without the effect; worse: S or gamma error grew; >u: by more than its stated u; "
         "half: both at most halved; cov, covsh: points within 2u_S, pointwise and shape; covg: "
         "gamma's points (about its constant and line) within 2u_gamma; hlf/idf: "
         "halved runs of those where the effect is identifiable from the plan, computed without "
         "the truth; idf/dbl: runs where the effect was identified of those where it doubled the "
         "clean S error; hlf/i+d: halved runs of those where the effect is identifiable from the "
         "plan and doubled the clean S error (S and gamma halved: the must-show's halving per "
         "cell); "
         "hwd/i+d: the same with gamma required to halve only where the effect doubled gamma's "
         "error)";
}

std::string sweep_row(const SweepCell& c) {
  char buf[512];
  std::snprintf(
      buf, sizeof buf,
      "%-12s %-12s %5.2f %4zu | %5.2f %5.2f %5.2f %5.2f %5.2f | %6.3f %6.3f %6.3f %6.3f %6.3f | "
      "%6.1f %6.1f %6.1f %6.1f | %5.2f %5.2f %5.2f | %5.3f %5.3f %5.3f | %3d/%-3d %3d/%-3d "
      "%3d/%-3d %3d/%-3d",
      to_string(c.effect), to_string(c.plan), c.sigma_um, c.runs.size(),
      c.fraction([](const SweepRun& r) { return r.added; }),
      c.fraction([](const SweepRun& r) { return r.identified; }),
      c.fraction([](const SweepRun& r) { return r.applied; }),
      c.fraction([](const SweepRun& r) { return r.not_white; }),
      c.fraction([](const SweepRun& r) { return r.not_identifiable_reported; }),
      c.median([](const SweepRun& r) { return r.S_clean_um; }),
      c.median([](const SweepRun& r) { return r.S_before_um; }),
      c.median([](const SweepRun& r) { return r.S_after_um; }),
      c.worst([](const SweepRun& r) { return r.S_before_um; }),
      c.worst([](const SweepRun& r) { return r.S_after_um; }),
      c.median([](const SweepRun& r) { return r.gamma_before_urad; }),
      c.median([](const SweepRun& r) { return r.gamma_after_urad; }),
      c.worst([](const SweepRun& r) { return r.gamma_before_urad; }),
      c.worst([](const SweepRun& r) { return r.gamma_after_urad; }),
      c.fraction([](const SweepRun& r) { return r.worse_S() || r.worse_gamma(); }),
      c.fraction([](const SweepRun& r) { return r.worse_beyond_u(); }),
      c.fraction([](const SweepRun& r) { return r.halved(); }), c.coverage(), c.coverage_shape(),
      c.coverage_gamma(),
      c.count([](const SweepRun& r) { return r.identifiable_from_plan && r.halved(); }),
      c.count([](const SweepRun& r) { return r.identifiable_from_plan; }),
      c.count([](const SweepRun& r) { return r.doubled() && r.identified; }),
      c.count([](const SweepRun& r) { return r.doubled(); }), c.count([](const SweepRun& r) {
        return r.identifiable_from_plan && r.doubled() && r.halved();
      }),
      c.count([](const SweepRun& r) { return r.identifiable_from_plan && r.doubled(); }),
      c.count([](const SweepRun& r) {
        return r.identifiable_from_plan && r.doubled() && r.halved_where_doubled();
      }),
      c.count([](const SweepRun& r) { return r.identifiable_from_plan && r.doubled(); }));
  return buf;
}

}  // namespace errsep::core
