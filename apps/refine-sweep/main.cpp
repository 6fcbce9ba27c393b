// errsep-refine-sweep: the refinement loop over generated scans with one undeclared effect each
// (issue 16): per effect and noise level, how often the effect is found, the errors of S and γ
// before and after (median and worst), how often the result was made worse, and the coverage of
// the refined u_S, and issue 16's must-show counts pooled over every cell and per sigma.  A
// benchmark that prints figures, not a test (tests/core/refine_undeclared.cpp asserts a smaller
// sweep; tests/core/refine_identifying_plan.cpp the --plan identifying cells, 20 seeds each).
//   errsep-refine-sweep [--seeds 20] [--sigma 0.05,0.1,0.2] [--effects all|name,...]
//                       [--declare effect=bound,...] [--plan single|closing|reversed|
//                       interleaved|rezeroed|identifying]
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "errsep/core/refine_sweep.hpp"
#include "errsep/version.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "errsep-refine-sweep: run the refinement loop (errsep-refine) over simulated four-sensor "
      "scans of random smooth profiles, each with one effect the model does not declare (every "
      "effect of the library, plus a sensor non-linearity, a bump and a hysteresis that it "
      "lacks; the sequence refine fits the hysteresis), and print "
      "per effect and noise level how often the effect is identified, the S and gamma errors "
      "before and after, how often the result was made worse and the coverage of u_S."};
  app.set_version_flag("--version", std::string("errsep ") + errsep::kVersion);
  int seeds = 20;
  std::uint64_t seed0 = 1;
  std::vector<double> sigmas = {0.05, 0.1, 0.2};
  std::vector<std::string> effects;
  double size = 1.0;
  bool per_run = false;
  app.add_option("--seeds", seeds, "runs per cell")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--seed0", seed0, "first seed")->capture_default_str();
  app.add_option("--sigma", sigmas, "noise levels, um")->delimiter(',')->capture_default_str();
  std::string effect_names;
  for (const auto e : errsep::core::all_undeclared_effects())
    effect_names += std::string(effect_names.empty() ? "" : ", ") + errsep::core::to_string(e);
  app.add_option("--effects", effects, "effects (" + effect_names + "); default all")
      ->delimiter(',');
  app.add_option("--size", size, "scale of the effects' drawn sizes")->capture_default_str();
  app.add_flag("--runs", per_run, "print every run");
  std::string plan = "single";
  app.add_option("--plan", plan,
                 std::string("the scan plan: ") + errsep::core::scan_sequence_kind_names() +
                     ", or identifying (each effect on the plan that identifies it, chosen by "
                     "the library's identifiability; the clean case on every plan used)")
      ->capture_default_str();
  bool verdicts = false;
  app.add_flag("--verdicts", verdicts, "with --runs: also the refine's verdict of every effect");
  errsep::core::RefineOptions refine;
  app.add_option("--max-error-ratio", refine.decision.max_error_ratio,
                 "apply a correction when the expected squared error with it is at most this "
                 "fraction of the one without it (step_decision.hpp)")
      ->capture_default_str();
  app.add_option("--max-quantity-increase", refine.decision.max_quantity_increase,
                 "... and no quantity's expected squared error grows by more than this fraction "
                 "of its noise")
      ->capture_default_str();
  app.add_option("--bias-z", refine.decision.bias_z,
                 "decide on the bias a correction removes at its lower confidence bound B - z "
                 "sd(B) (step_decision.hpp)")
      ->capture_default_str();
  app.add_option("--reading-bound", refine.reading_bound,
                 "hold an effect's term in u_S at this many times the readings' RMS and say u_S "
                 "is unbounded beyond it; 0: off (refine.hpp RefineOptions::reading_bound)")
      ->capture_default_str();
  app.add_option("--spike-cluster", refine.gross.cluster_positions,
                 "spikes of one configuration within this many positions are a shape, not "
                 "removed; 0: off (gross_errors.hpp GrossErrorOptions::cluster_positions)")
      ->capture_default_str();
  app.add_option("--apply-unidentifiable", refine.apply_unidentifiable,
                 "apply the determined part of an effect this plan cannot identify (refine.hpp)")
      ->capture_default_str();
  app.add_option("--apply-requires-identifiable", refine.apply_requires_identifiable,
                 "apply a correction only where effect_identifiability says the plan lets it "
                 "halve the errors (refine.hpp)")
      ->capture_default_str();
  errsep::core::SequenceRefineOptions seq_opts;
  app.add_option("--hysteresis-signs-from-readings", seq_opts.hysteresis_signs_from_readings,
                 "a scan sequence's hysteresis: weigh the lag's sign at the profile's turns by "
                 "the readings too; 0: the fitted slope's sign alone (sequence_refine.hpp)")
      ->capture_default_str();
  std::vector<std::string> declared;
  app.add_option("--declare", declared,
                 "declared bounds (Type B) as effect=bound, e.g. drift=0.03,thermal=5: every "
                 "parameter of the effect within +-bound in its units (refine.hpp "
                 "DeclaredEffectBound)")
      ->delimiter(',');
  CLI11_PARSE(app, argc, argv);

  try {
    std::vector<errsep::core::UndeclaredEffect> list;
    if (effects.empty()) {
      list = errsep::core::all_undeclared_effects();
    } else {
      for (const auto& e : effects) {
        const auto k = errsep::core::undeclared_effect_from_string(e);
        if (!k) throw std::invalid_argument("--effects: unknown effect '" + e + "'");
        list.push_back(*k);
      }
    }
    for (const auto& d : declared) {
      const auto eq = d.find('=');
      std::size_t used = 0;
      double b = 0;
      try {
        if (eq != std::string::npos) b = std::stod(d.substr(eq + 1), &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (eq == std::string::npos || used == 0 || eq + 1 + used != d.size())
        throw std::invalid_argument("--declare: '" + d + "' is not effect=bound");
      refine.declared.push_back({d.substr(0, eq), b});
    }
    errsep::core::UndeclaredCaseOptions base;
    base.size = size;
    std::string why;
    if (!base.is_valid(&why)) throw std::invalid_argument(why);
    if (!refine.is_valid(&why)) throw std::invalid_argument(why);
    std::vector<std::string> skipped;
    const auto cells = errsep::core::sweep_plan_cells(plan, list, &skipped);
    for (const auto& s : skipped)
      std::cout << "skipped " << s << "\n";
    if (plan == "identifying")
      for (const auto& c : cells)
        std::cout << "plan for " << errsep::core::to_string(c.effect) << ": "
                  << errsep::core::to_string(c.plan) << " (" << c.why << ")\n";
    std::cout << errsep::core::sweep_header() << "\n";
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::string> breakdown;
    std::vector<errsep::core::SweepCell> all_cells;
    for (const auto& pc : cells)
      for (const double s : sigmas) {
        const auto cell = errsep::core::run_sweep_cell_on(pc.plan, pc.effect, s, seeds, seed0,
                                                          refine, base, seq_opts);
        breakdown.push_back(errsep::core::coverage_breakdown(cell));
        all_cells.push_back(cell);
        std::cout << errsep::core::sweep_row(cell) << std::endl;
        if (per_run)
          for (const auto& r : cell.runs) {
            char buf[600];
            std::snprintf(buf, sizeof buf,
                          "    seed %3llu S %.3f -> %.3f (clean %.3f, u %.3f) g %.1f -> %.1f (u "
                          "%.1f)%s | %s | %s",
                          static_cast<unsigned long long>(r.seed), r.S_before_um, r.S_after_um,
                          r.S_clean_um, r.u_S_after_um, r.gamma_before_urad, r.gamma_after_urad,
                          r.u_gamma_after_urad, r.worse_beyond_u() ? " WORSE BEYOND u" : "",
                          r.model.c_str(), r.description.c_str());
            std::cout << buf << "\n";
            if (verdicts && !r.verdicts.empty()) std::cout << "      " << r.verdicts << "\n";
            if (verdicts && !r.identifiability.empty())
              std::cout << "      " << r.identifiability << "\n";
          }
      }
    for (const auto& b : breakdown)
      std::cout << b << "\n";
    // Pooled over every cell (core::MustShow counts them; nothing summed here).
    std::cout << "must show: " << errsep::core::must_show(all_cells).brief() << "\n";
    for (const double s : sigmas) {
      std::vector<errsep::core::SweepCell> at;
      for (const auto& c : all_cells)
        if (c.sigma_um == s) at.push_back(c);
      std::printf("must show at sigma %.2f: %s\n", s, errsep::core::must_show(at).brief().c_str());
    }
    std::printf("total %.1f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "errsep-refine-sweep: " << e.what() << "\n";
    return 1;
  }
}
