// Issue 16 (branch unone16): per run of the single-scan refine on simulate_undeclared's cases,
// what the refine corrected and the terms of its u_S.  Research tool, not built by CMake:
//   cd build && c++ -I../include -Igenerated -isystem /usr/include/eigen3 -O2 -std=c++20 \
//     ../tools/proto/refine_u_terms.cpp -o /tmp/refine_u_terms src/service/liberrsep_service.a \
//     src/drivers/liberrsep_drivers.a src/acq/liberrsep_acq.a src/io/liberrsep_io.a \
//     src/core/liberrsep_core.a -lcholmod -lsuitesparseconfig -ltomlplusplus -lmodbus -lgpiod \
//     -lmosquitto
//   /tmp/refine_u_terms [-e effect]... [-s first last] [-g sigma]
// One line per run: effects added, applied, gross errors removed/found, non-linearity
// detected/corrected, σ̂ of the raw and refined separations and of a fresh separation of the
// corrected readings, u_S RMS (raw, fresh, the effects' term, the gauge floor, final), the
// smallest refined/raw u_S ratio over the points, coverage (points within 2 u_S) raw -> refined,
// S error raw -> refined; then per cell the counts of runs whose u_S fell below the raw one.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include "errsep/core/refine.hpp"
#include "errsep/core/refine_sweep.hpp"
#include "errsep/core/undeclared_effect_simulation.hpp"
using namespace errsep::core;
static double rms(const Eigen::VectorXd& v) {
  return v.size() ? std::sqrt(v.squaredNorm() / v.size()) : 0;
}
int main(int argc, char** argv) {
  std::vector<std::string> effs;
  std::vector<double> sig = {0.05, 0.1, 0.2};
  int s0 = 1, s1 = 40;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "-e")
      effs.push_back(argv[++i]);
    else if (a == "-s") {
      s0 = atoi(argv[++i]);
      s1 = atoi(argv[++i]);
    } else if (a == "-g")
      sig = {atof(argv[++i])};
  }
  std::vector<UndeclaredEffect> list;
  if (effs.empty())
    list = all_undeclared_effects();
  else
    for (auto& e : effs)
      list.push_back(*undeclared_effect_from_string(e));
  for (auto ef : list)
    for (double s : sig) {
      int below_none = 0, none = 0, below_added = 0, added_n = 0, declined_only = 0,
          rms_below_added = 0;
      long pts = 0, cov_b = 0, cov_a = 0;
      for (int seed = s0; seed <= s1; ++seed) {
        UndeclaredCaseOptions co;
        co.sigma_um = s;
        co.seed = seed;
        const UndeclaredCase c = simulate_undeclared(ef, co);
        RefineOptions ro;
        const RefineResult r = refine_four_sensor(c.cfg, c.m_um, c.t_s, ro);
        const FourSensorResult fresh = separate_four_sensor(c.cfg, r.m_corrected_um, ro.solve);
        int nap = 0;
        for (bool a : r.applied)
          nap += a;
        int ngr = 0, ngrrem = 0;
        for (auto& g : r.gross.errors) {
          ++ngr;
          ngrrem += g.applied;
        }
        const double ub = rms(r.before.u_S_um), ua = rms(r.after.u_S_um);
        const double minratio = (r.after.u_S_um.array() / r.before.u_S_um.array()).minCoeff();
        const Eigen::VectorXd dSb = r.before.S_um - c.S_um, dSa = r.after.S_um - c.S_um;
        int cb = 0, ca = 0;
        for (int n = 0; n < dSa.size(); ++n) {
          cb += std::abs(dSb(n)) <= 2 * r.before.u_S_um(n);
          ca += std::abs(dSa(n)) <= 2 * r.after.u_S_um(n);
        }
        pts += dSa.size();
        cov_b += cb;
        cov_a += ca;
        const bool added = nap > 0 || ngrrem > 0 || r.nonlinearity.applied;  // something corrected
        if (!added && rms(r.after.u_S_um) < ub * (1 - 1e-9)) std::printf("RMSBELOW ");
        if (!r.effects.empty() && nap == 0 && ngrrem == 0 && !r.nonlinearity.applied)
          ++declined_only;
        if (added && ua < ub) ++rms_below_added;
        const bool below = minratio < 1 - 1e-9;
        if (added) {
          ++added_n;
          below_added += below;
        } else {
          ++none;
          below_none += below;
        }
        std::printf(
            "%-12s %.2f %3d add %zu appl %d gross %d/%d nl %d/%d | sig_b %.3f sig_a %.3f sig_fresh "
            "%.3f | uS raw %.3f fresh %.3f eff %.3f gauge %.3f final %.3f min ratio %.3f | cov "
            "%d->%d/%ld | S %.3f->%.3f %s\n",
            to_string(ef), s, seed, r.effects.size(), nap, ngrrem, ngr,
            (int)r.nonlinearity.detected, (int)r.nonlinearity.applied, r.before.sigma_um,
            r.after.sigma_um, fresh.sigma_um, ub, rms(fresh.u_S_um), rms(r.u_S_effects_um),
            rms(r.u_S_gauge_um), ua, minratio, cb, ca, (long)dSa.size(),
            profile_errors(r.before, RefineTruth{c.f_um, c.S_um, c.gamma_rad}).S_um,
            profile_errors(r.after, RefineTruth{c.f_um, c.S_um, c.gamma_rad}).S_um,
            r.model_name.c_str());
      }
      std::printf(
          "CELL %-12s %.2f seeds %d-%d: pointwise below raw with nothing applied %d/%d (of them "
          "effects added, all declined: %d), with something applied %d/%d (rms below %d); cov "
          "before %.3f after %.3f\n",
          to_string(ef), s, s0, s1, below_none, none, declined_only, below_added, added_n,
          rms_below_added, double(cov_b) / pts, double(cov_a) / pts);
      std::fflush(stdout);
    }
}
