// The uncertainty of a four-sensor separation predicted before measuring
// (predict_four_sensor_uncertainty, four_sensor_posterior.hpp) against a dense reference built
// here from its definition: the unregularised separation is linear in the readings, S = J·m, so
// its covariance for independent noise σ on every reading is σ²·J·Jᵀ, with J found column by
// column by separating unit readings.  Also: a configuration whose normal matrix has an exact zero
// inside the band (spacings (2, 3, 10)) gets its u_S from the selected inverse.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>

#include "errsep/core/four_sensor.hpp"
#include "errsep/core/four_sensor_simulation.hpp"

using namespace errsep::core;

namespace {

FourSensorOptions least_squares() {
  FourSensorOptions o;
  o.penalty = Penalty::none;
  o.rule = LambdaRule::least_squares;
  o.compute_uncertainty = false;
  return o;
}

// J (P × 4P, S per unit reading) and the same for γ, column 4n + j = reading j at position n.
void jacobians(const FourSensorConfig& cfg, Eigen::MatrixXd& JS, Eigen::MatrixXd& Jg) {
  const int P = cfg.positions();
  JS.resize(P, 4 * P);
  Jg.resize(P, 4 * P);
  for (int n = 0; n < P; ++n)
    for (int j = 0; j < 4; ++j) {
      Eigen::MatrixXd m = Eigen::MatrixXd::Zero(P, 4);
      m(n, j) = 1.0;
      const FourSensorResult r = separate_four_sensor(cfg, m, least_squares());
      JS.col(4 * n + j) = r.S_um;
      Jg.col(4 * n + j) = r.gamma_rad;
    }
}

}  // namespace

TEST_CASE("predicted u_S, u_gamma and covariances equal the dense sigma^2 J J^T",
          "[four_sensor][prediction]") {
  for (const FourSensorConfig cfg :
       {FourSensorConfig{5.0, 1, 1, 5, 40}, FourSensorConfig{2.0, 2, 3, 10, 60},
        FourSensorConfig{1.0, 4, 1, 6, 47}}) {
    INFO("spacings " << cfg.s2 << "," << cfg.s3 << "," << cfg.s4 << " N " << cfg.N);
    const double sigma = 0.07;
    Eigen::MatrixXd JS, Jg;
    jacobians(cfg, JS, Jg);
    const Eigen::MatrixXd VS = sigma * sigma * JS * JS.transpose();
    const Eigen::MatrixXd Vg = sigma * sigma * Jg * Jg.transpose();
    const FourSensorPrediction p = predict_four_sensor_uncertainty(cfg, sigma);
    const int P = cfg.positions();
    REQUIRE(p.u_S_um.size() == P);
    REQUIRE(p.u_gamma_rad.size() == P);
    const Eigen::VectorXd uS = VS.diagonal().cwiseSqrt(), ug = Vg.diagonal().cwiseSqrt();
    CHECK((p.u_S_um - uS).cwiseAbs().maxCoeff() <= 1e-8 * uS.maxCoeff());
    CHECK((p.u_gamma_rad - ug).cwiseAbs().maxCoeff() <= 1e-8 * ug.maxCoeff());
    // The covariance of the whole profile with a line's two functionals (and a random one).
    Eigen::MatrixXd a(P, 3);
    a.col(0).setOnes();
    a.col(1) = p.x_mm;
    a.col(2) = Eigen::VectorXd::Random(P);
    const Eigen::MatrixXd C = p.covariance->covariance_S_with(a);
    const Eigen::MatrixXd C_ref = VS * a;
    CHECK((C - C_ref).cwiseAbs().maxCoeff() <= 1e-8 * C_ref.cwiseAbs().maxCoeff());
    CHECK_THROWS_AS(p.covariance->covariance_S_with(Eigen::MatrixXd::Ones(P + 1, 1)),
                    std::invalid_argument);
  }
}

TEST_CASE("the prediction is what the least-squares separation of any data states for its sigma",
          "[four_sensor][prediction]") {
  // The stated u_S of a separation scales with its σ̂ only: data with other profiles and noise
  // give the same shape, and the prediction at that σ is the same vector.
  const FourSensorConfig cfg{5.0, 2, 3, 10, 120};
  FourSensorOptions o = least_squares();
  o.compute_uncertainty = true;
  for (const std::uint64_t seed : {3u, 4u}) {
    FourSensorSimOptions so;
    so.sigma_um = 0.1;
    so.seed = seed;
    const FourSensorSimData sim = simulate_four_sensor(cfg, random_smooth_truth(cfg, seed), so);
    const FourSensorResult r = separate_four_sensor(cfg, sim.m_um, o);
    const FourSensorPrediction p = predict_four_sensor_uncertainty(cfg, r.sigma_um);
    CHECK((r.u_S_um - p.u_S_um).cwiseAbs().maxCoeff() <= 1e-9 * p.u_S_um.maxCoeff());
  }
}

TEST_CASE("spacings with an exact zero in the normal matrix: the default estimator states u_S",
          "[four_sensor][prediction]") {
  // (2, 3, 10): offsets 0, 2, 5, 15, and a zero of QQᵀ leaves a pair of unknowns that u_S at
  // the first positions couples outside the pattern of the factor (it threw out_of_range).
  const FourSensorConfig cfg{5.0, 2, 3, 10, 120};
  FourSensorSimOptions so;
  so.sigma_um = 0.1;
  so.seed = 11;
  const FourSensorSimData sim = simulate_four_sensor(cfg, random_smooth_truth(cfg, 11), so);
  const FourSensorResult r = separate_four_sensor(cfg, sim.m_um);
  REQUIRE(r.u_S_um.size() == cfg.positions());
  CHECK(r.u_S_um.minCoeff() > 0.0);
  CHECK(r.u_S_um.allFinite());
}

TEST_CASE("prediction: bad sigma and configurations are refused", "[four_sensor][prediction]") {
  CHECK_THROWS_AS(predict_four_sensor_uncertainty(FourSensorConfig{}, 0.0), std::invalid_argument);
  CHECK_THROWS_AS(predict_four_sensor_uncertainty(FourSensorConfig{}, std::nan("")),
                  std::invalid_argument);
  CHECK_THROWS_AS(predict_four_sensor_uncertainty(FourSensorConfig{5.0, 2, 2, 4, 69}, 0.1),
                  std::invalid_argument);
}
