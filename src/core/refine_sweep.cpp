#include "errsep/core/refine_sweep.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace errsep::core {

namespace {

double rms(const Eigen::VectorXd& v) {
  return v.size() ? std::sqrt(v.squaredNorm() / static_cast<double>(v.size())) : 0.0;
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

int SweepCell::identifiable_runs() const {
  return static_cast<int>(std::count_if(
      runs.begin(), runs.end(), [](const SweepRun& r) { return r.identifiable_from_plan; }));
}

int SweepCell::halved_identifiable_runs() const {
  return static_cast<int>(std::count_if(runs.begin(), runs.end(), [](const SweepRun& r) {
    return r.identifiable_from_plan && r.halved();
  }));
}

double SweepCell::coverage() const {
  long in = 0, all = 0;
  for (const auto& r : runs)
    in += r.covered, all += r.points;
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
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "%-12s %5.2f coverage within 2 u_S: %.3f; applied %.3f (%d runs), detected not "
                "applied %.3f (%d), nothing added %.3f (%d); u_S widened in %zu (median x%.2f, "
                "max x%.2f)",
                to_string(c.effect), c.sigma_um, c.coverage(), ca, na, cd, nd, cn, nn, ratio.size(),
                ratio.empty() ? 1.0 : ratio[ratio.size() / 2], ratio.empty() ? 1.0 : ratio.back());
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

std::string sweep_header() {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "%-12s %5s %4s | %5s %5s %5s %5s %5s | %6s %6s %6s %6s %6s | %6s %6s %6s %6s | "
                "%5s %5s %5s | %5s %5s | %7s",
                "effect", "sigma", "runs", "added", "ident", "appl", "!wht", "!idp", "S_cln",
                "S_bef", "S_aft", "Sbef^", "Saft^", "g_bef", "g_aft", "gbef^", "gaft^", "worse",
                ">u", "half", "cov", "covsh", "hlf/idf");
  return std::string(buf) +
         "\n  (fractions of runs; errors RMS in um / urad, median and ^ worst; S_cln: the same "
         "scan without the effect; worse: S or gamma error grew; >u: by more than its stated u; "
         "half: both at most halved; cov, covsh: points within 2u, pointwise and shape; hlf/idf: "
         "halved runs of those where the effect is identifiable from the plan, computed without "
         "the truth)";
}

std::string sweep_row(const SweepCell& c) {
  char buf[400];
  std::snprintf(
      buf, sizeof buf,
      "%-12s %5.2f %4zu | %5.2f %5.2f %5.2f %5.2f %5.2f | %6.3f %6.3f %6.3f %6.3f %6.3f | %6.1f "
      "%6.1f %6.1f %6.1f | %5.2f %5.2f %5.2f | %5.3f %5.3f | %3d/%-3d",
      to_string(c.effect), c.sigma_um, c.runs.size(),
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
      c.halved_identifiable_runs(), c.identifiable_runs());
  return buf;
}

}  // namespace errsep::core
