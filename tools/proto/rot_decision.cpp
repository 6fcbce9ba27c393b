// Issue 16 (branch rot16): per run of the two-axis separation and refine on the diagonal-plan
// thermal case of tests/apps/displacement_app.cpp, why the automatic rotation decision goes on.
// Research tool, not built by CMake:
//   cd build && c++ -I../include -I../tests -Igenerated -isystem /usr/include/eigen3 -O2 \
//     -std=c++20 ../tools/proto/rot_decision.cpp -o /tmp/rot_decision src/core/liberrsep_core.a \
//     -lcholmod -lsuitesparseconfig
//   /tmp/rot_decision [case] [sigma] [first] [last]   case: clean, drift34, driftall, roll
//   (roll: 600 sigma urad peak to peak); env MERR=1, FITS=1, NOTE=1 print more per run.
#include <Eigen/Dense>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "errsep/core/displacement_refine.hpp"
#include "errsep/core/displacement_simulation.hpp"
#include "support/displacement_cases.hpp"
using namespace errsep::core;

static double shape_rms(const Eigen::MatrixXd& e) {
  const Eigen::ArrayXXd a = e.array() - e.mean();
  return std::sqrt(a.square().mean());
}
static double rms(const Eigen::MatrixXd& e) {
  return std::sqrt(e.array().square().mean());
}

int main(int argc, char** argv) {
  const std::string cs = argc > 1 ? argv[1] : "drift34";
  const double sigma = argc > 2 ? std::atof(argv[2]) : 0.1;
  const int first = argc > 3 ? std::atoi(argv[3]) : 1601,
            last = argc > 4 ? std::atoi(argv[4]) : 1620;
  constexpr int kN = 20;
  TwoAxisScanOrder order;
  order.sample_period_s = 1.0;
  order.pause_between_scans_s = 60.0;
  order.reverse_scan2 = true;
  order.y_fastest_scan2 = true;
  order.diagonal_scan1 = true;
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(kN, 0.0, 5.0 * (kN - 1));
  TwoAxisOptions sep;
  const auto lib = make_displacement_effect_library(x, x, true, order, sep);
  std::printf(
      "seed  tau  a3 a4 | pred_on pred_off bias | err_on err_off u_on u_off | auto | sig_hat/sig | "
      "b_shape u_b | refined: steps appl err(auto) u(auto) rot\n");
  for (int seed = first; seed <= last; ++seed) {
    TwoAxisSimOptions so;
    so.nx = so.ny = kN;
    so.eddy_sensor.noise_sigma_um = sigma;
    so.contact_sensor.noise_sigma_um = 1.8 * sigma;
    so.record_s0_scan2 = true;
    so.seed = static_cast<std::uint64_t>(seed);
    so.timing.sample_period_s = 1.0;
    so.timing.pause_between_scans_s = 60.0;
    so.reverse_scan2 = so.y_fastest_scan2 = so.diagonal_scan1 = true;
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed) * 131 + 5);
    std::uniform_real_distribution<double> size(1.5 * sigma, 3.0 * sigma);
    double rot = 0;
    if (cs == "drift34" || cs == "driftall") {
      for (int k = 0; k < 5; ++k)
        if (cs == "driftall" || k >= 3)
          so.disturbance.thermal_um[static_cast<std::size_t>(k)] =
              (rng() % 2 ? 1.0 : -1.0) * size(rng);
      so.disturbance.thermal_tau_s =
          kN * kN *
          std::exp(std::uniform_real_distribution<double>(std::log(0.3), std::log(3.0))(rng));
    }
    if (cs == "roll") rot = 600.0 * sigma;
    const auto truth = errsep::test::random_two_axis_truth(static_cast<std::uint64_t>(seed), rot);
    const auto sim = simulate_two_axis(truth, so);
    TwoAxisResult r[3];
    const RotationCorrection modes[3] = {RotationCorrection::on, RotationCorrection::off,
                                         RotationCorrection::automatic};
    for (int q = 0; q < 3; ++q) {
      TwoAxisOptions o;
      o.rotation = modes[q];
      r[q] = separate_two_axis(sim.scan, o);
    }
    const double e_on = shape_rms(r[0].w_um - sim.w_um), e_off = shape_rms(r[1].w_um - sim.w_um);
    const Eigen::MatrixXd b = r[0].m_wxe_um + r[0].m_wye_um;
    const Eigen::MatrixXd ub2 = r[0].u_m_wxe_um.array().square() + r[0].u_m_wye_um.array().square();
    const auto gt = errsep::test::gauged_truth(truth, sim, so.geometry, false);
    if (std::getenv("MERR"))
      std::printf(
          "   m errors (shape rms) m1 %.3f m2 %.3f m3 %.3f m4 %.3f  m4-m3 %.3f m2-m1 %.3f\n",
          shape_rms(r[1].m1x_um - gt.m[0]), shape_rms(r[1].m2x_um - gt.m[1]),
          shape_rms(r[1].m3y_um - gt.m[2]), shape_rms(r[1].m4y_um - gt.m[3]),
          shape_rms(r[1].m4y_um - r[1].m3y_um - gt.m[3] + gt.m[2]),
          shape_rms(r[1].m2x_um - r[1].m1x_um - gt.m[1] + gt.m[0]));
    if (std::getenv("FITS")) {
      const Eigen::VectorXd res = displacement_redundancy_residual(sim.scan);
      const Eigen::Index N = kN * kN;
      Eigen::VectorXd wt(res.size());
      wt.head(4 * N).setConstant(1.0 / (std::sqrt(2.0) * r[0].sigma_reference_um));
      wt.tail(N).setConstant(1.0 / (std::sqrt(2.0) * r[0].sigma_workpiece_um));
      const Eigen::VectorXd y = wt.cwiseProduct(res);
      for (const auto& e : lib.effects) {
        if (e.family == "tilt") continue;
        const Eigen::MatrixXd X = wt.asDiagonal() * e.residual_columns;
        const Eigen::MatrixXd XtX = X.transpose() * X;
        const Eigen::VectorXd beta = XtX.ldlt().solve(X.transpose() * y);
        const double dchi = y.squaredNorm() - (y - X * beta).squaredNorm();
        const Eigen::MatrixXd C = XtX.inverse();
        double sh[2], fl[2];
        for (int q = 0; q < 2; ++q) {
          Eigen::MatrixXd D = e.d_w[q];
          D.rowwise() -= D.colwise().mean();
          sh[q] = shape_rms(Eigen::MatrixXd(D * beta));
          fl[q] = std::sqrt((D * C).cwiseProduct(D).rowwise().sum().mean());
        }
        std::printf(
            "   %-22s dchi2 %7.1f  w(off) %.3f +- %.3f  w(on) %.3f +- %.3f  a3 %.3f a4 %.3f\n",
            e.name.c_str(), dchi, sh[0], fl[0], sh[1], fl[1], beta(3), beta(4));
      }
    }
    TwoAxisOptions o;
    const auto ref = refine_two_axis(sim.scan, o, lib);
    int appl = 0;
    for (const auto& s : ref.steps)
      appl += s.applied;
    std::printf(
        "%d %5.0f %6.3f %6.3f | %.3f %.3f %.3f | %.3f %.3f %.3f %.3f | %s | %.3f | %.3f %.3f | %zu "
        "%d %.3f %.3f %s\n",
        seed, so.disturbance.thermal_tau_s, so.disturbance.thermal_um[3],
        so.disturbance.thermal_um[4], r[0].predicted_rms_on_um, r[0].predicted_rms_off_um, 0.0,
        e_on, e_off, rms(r[0].u_w_um), rms(r[1].u_w_um), r[2].rotation_corrected ? "on " : "off",
        r[0].sigma_reference_um / sigma, shape_rms(b), std::sqrt(ub2.mean()), ref.steps.size(),
        appl, shape_rms(ref.refined.w_um - sim.w_um), rms(ref.refined.u_w_um),
        ref.refined.rotation_corrected ? "on" : "off");
    if (std::getenv("NOTE")) {
      for (const auto& n : ref.not_identifiable)
        std::printf("     note: %s\n", n.c_str());
      for (const auto& st : ref.steps)
        std::printf("     step: %s\n", st.line.c_str());
    }
  }
}
