#include "errsep/core/displacement_residuals.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>

namespace errsep::core {
namespace {

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("displacement residuals: " + what);
}

// Least-squares fit of one constant per group (the group mean) and what it leaves.
void fit_groups(ResidualChannel& ch, int groups) {
  const auto L = ch.value_um.size();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(groups), count = Eigen::VectorXd::Zero(groups);
  for (Eigen::Index t = 0; t < L; ++t) {
    sum(ch.group[static_cast<std::size_t>(t)]) += ch.value_um(t);
    count(ch.group[static_cast<std::size_t>(t)]) += 1.0;
  }
  ch.group_mean_um = Eigen::VectorXd::Zero(groups);
  int used = 0;
  for (int g = 0; g < groups; ++g)
    if (count(g) > 0) {
      ch.group_mean_um(g) = sum(g) / count(g);
      ++used;
    }
  ch.residual_um.resize(L);
  for (Eigen::Index t = 0; t < L; ++t)
    ch.residual_um(t) = ch.value_um(t) - ch.group_mean_um(ch.group[static_cast<std::size_t>(t)]);
  ch.dof = static_cast<int>(L) - used;
  ch.rss_um2 = ch.residual_um.squaredNorm();
  ch.sigma_um = ch.dof > 0 ? std::sqrt(ch.rss_um2 / (ch.variance_factor * ch.dof)) : 0.0;
}

// Π of a group model applied to one column: the column minus its group means.
Eigen::VectorXd remove_group_means(const Eigen::VectorXd& v, const std::vector<int>& group,
                                   int groups) {
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(groups), count = Eigen::VectorXd::Zero(groups);
  for (Eigen::Index t = 0; t < v.size(); ++t) {
    sum(group[static_cast<std::size_t>(t)]) += v(t);
    count(group[static_cast<std::size_t>(t)]) += 1.0;
  }
  Eigen::VectorXd out(v.size());
  for (Eigen::Index t = 0; t < v.size(); ++t) {
    const int g = group[static_cast<std::size_t>(t)];
    out(t) = v(t) - sum(g) / count(g);
  }
  return out;
}

ResidualChannel make_channel(std::string name, int sensor, int scan, Eigen::VectorXd value,
                             std::vector<int> group, int groups, double variance_factor) {
  ResidualChannel ch;
  ch.name = std::move(name);
  ch.sensor = sensor;
  ch.scan = scan;
  ch.value_um = std::move(value);
  ch.group = std::move(group);
  ch.variance_factor = variance_factor;
  fit_groups(ch, groups);
  return ch;
}

// Pooled σ̂, its interval and the whiteness test of all channels together.
void finish_family(RedundancyFamily& f, const DisplacementResidualOptions& o) {
  const auto L = f.x_mm.size();
  const auto C = static_cast<Eigen::Index>(f.channels.size());
  double cdof = 0;
  f.equations = 0;
  f.dof = 0;
  f.rss_um2 = 0;
  for (const auto& ch : f.channels) {
    f.equations += static_cast<int>(ch.value_um.size());
    f.dof += ch.dof;
    f.rss_um2 += ch.rss_um2;
    cdof += ch.variance_factor * ch.dof;
  }
  if (f.dof > 0) {
    f.sigma_um = std::sqrt(f.rss_um2 / cdof);
    const boost::math::chi_squared chi(f.dof);
    const double lo = boost::math::quantile(chi, 0.5 * (1.0 - o.confidence));
    const double hi = boost::math::quantile(chi, 0.5 * (1.0 + o.confidence));
    f.sigma_low_um = f.sigma_um * std::sqrt(f.dof / hi);
    f.sigma_high_um = f.sigma_um * std::sqrt(f.dof / lo);
  }
  ProjectedResidual pr;
  pr.residual.resize(L, C);
  pr.projector_diagonal.resize(L, C);
  std::vector<std::vector<int>> groups(static_cast<std::size_t>(C));
  std::vector<int> ngroups(static_cast<std::size_t>(C));
  for (Eigen::Index c = 0; c < C; ++c) {
    const auto& ch = f.channels[static_cast<std::size_t>(c)];
    pr.residual.col(c) = ch.residual_um;
    groups[static_cast<std::size_t>(c)] = ch.group;
    ngroups[static_cast<std::size_t>(c)] = static_cast<int>(ch.group_mean_um.size());
    std::vector<int> count(static_cast<std::size_t>(ch.group_mean_um.size()), 0);
    for (int g : ch.group)
      ++count[static_cast<std::size_t>(g)];
    for (Eigen::Index t = 0; t < L; ++t)
      pr.projector_diagonal(t, c) =
          1.0 - 1.0 / count[static_cast<std::size_t>(ch.group[static_cast<std::size_t>(t)])];
  }
  pr.project = [groups, ngroups](const Eigen::MatrixXd& z) {
    Eigen::MatrixXd out(z.rows(), z.cols());
    for (Eigen::Index c = 0; c < z.cols(); ++c)
      out.col(c) = remove_group_means(z.col(c), groups[static_cast<std::size_t>(c)],
                                      ngroups[static_cast<std::size_t>(c)]);
    return out;
  };
  f.whiteness = test_projected_whiteness(pr, o.whiteness, &f.periodogram_power);
  const auto centre =
      std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::lround(f.whiteness.local_x_mm)), 0,
                               std::max<Eigen::Index>(0, L - 1));
  if (L > 0) {
    f.local_x_mm = f.x_mm(centre);
    f.local_y_mm = f.y_mm(centre);
  }
  f.local_instants = static_cast<int>(std::lround(f.whiteness.local_width_mm));
}

void finish(DisplacementResiduals& out, const DisplacementResidualOptions& o) {
  out.alpha = o.whiteness.alpha;
  out.dof = 0;
  out.white = true;
  const double level = out.families.empty()
                           ? o.whiteness.alpha
                           : o.whiteness.alpha / static_cast<double>(out.families.size());
  for (auto& f : out.families) {
    out.dof += f.dof;
    if (f.dof > 0 && f.whiteness.p_value < level) out.white = false;
  }
}

std::string fmt(const char* format, double a) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, a);
  return buf;
}

void check_finite(const Eigen::MatrixXd& m, const std::string& what) {
  require(m.allFinite(), "non-finite value in " + what);
}

}  // namespace

bool DisplacementResidualOptions::is_valid(std::string* why) const {
  if (!whiteness.is_valid(why)) return false;
  if ((whiteness.mc_samples + 1.0) * whiteness.alpha / 3.0 <= 1.0) {
    if (why)
      *why = "whiteness.mc_samples = " + std::to_string(whiteness.mc_samples) +
             " cannot reach alpha/3 = " + std::to_string(whiteness.alpha / 3.0) +
             " (up to three families, Bonferroni): need (mc_samples + 1) * alpha / 3 > 1";
    return false;
  }
  if (!(confidence > 0 && confidence < 1)) {
    if (why) *why = "confidence = " + std::to_string(confidence) + ": must be in (0, 1)";
    return false;
  }
  return true;
}

const char* to_string(RedundancyKind k) {
  switch (k) {
    case RedundancyKind::reference_pieces:
      return "reference_pieces";
    case RedundancyKind::workpiece_repeat:
      return "workpiece_repeat";
    case RedundancyKind::repeated_runs:
      return "repeated_runs";
  }
  return "unknown";
}

std::string RedundancyFamily::brief_report() const {
  std::string s = std::string(to_string(kind)) + ": " + std::to_string(equations) +
                  " equations, dof " + std::to_string(dof);
  if (dof == 0) return s + ", nothing redundant";
  s += ", sigma_hat " + fmt("%.4g", sigma_um) + " um [" + fmt("%.4g", sigma_low_um) + ", " +
       fmt("%.4g", sigma_high_um) + "]";
  if (channels.size() > 1) {
    s += " (";
    for (std::size_t c = 0; c < channels.size(); ++c)
      s += (c ? ", " : "") + channels[c].name + " " + fmt("%.4g", channels[c].sigma_um);
    s += ")";
  }
  s += whiteness.white ? ", white" : ", NOT white";
  s += " (p = " + fmt("%.3g", whiteness.p_value);
  if (!whiteness.rejected_by.empty()) s += "; rejected by " + whiteness.rejected_by;
  s += ")";
  return s;
}

std::string DisplacementResiduals::brief_report() const {
  std::string s = "displacement residuals: ";
  if (families.empty()) return s + "none (" + note + ")";
  s += std::to_string(dof) + " dof in " + std::to_string(families.size()) +
       (families.size() == 1 ? " family" : " families") + ", " +
       (white ? "white" : "NOT white: the model lacks something") + " (alpha " +
       fmt("%.3g", alpha) + (families.size() > 1 ? " over the families)" : ")");
  for (const auto& f : families)
    s += "\n  " + f.brief_report();
  if (!note.empty()) s += "\n  note: " + note;
  return s;
}

OneAxisRun mean_of_runs(const std::vector<OneAxisRun>& runs) {
  require(!runs.empty(), "no runs");
  OneAxisRun m = runs.front();
  const bool s12 = std::all_of(runs.begin(), runs.end(),
                               [](const OneAxisRun& r) { return r.s1_2_um.size() > 0; });
  if (!s12) m.s1_2_um.resize(0);
  for (std::size_t q = 1; q < runs.size(); ++q) {
    const auto& r = runs[q];
    require(r.s1_1_um.size() == m.s1_1_um.size() && r.s2_1_um.size() == m.s2_1_um.size() &&
                r.s2_2_um.size() == m.s2_2_um.size(),
            "run " + std::to_string(q + 1) + " differs in length from run 1");
    m.s1_1_um += r.s1_1_um;
    m.s2_1_um += r.s2_1_um;
    m.s2_2_um += r.s2_2_um;
    if (s12) {
      require(r.s1_2_um.size() == m.s1_2_um.size(),
              "run " + std::to_string(q + 1) + " differs in length from run 1");
      m.s1_2_um += r.s1_2_um;
    }
  }
  const double R = static_cast<double>(runs.size());
  for (auto* v : {&m.s1_1_um, &m.s2_1_um, &m.s2_2_um, &m.s1_2_um})
    *v /= R;
  return m;
}

TwoAxisScan mean_of_runs(const std::vector<TwoAxisScan>& runs) {
  require(!runs.empty(), "no runs");
  TwoAxisScan m = runs.front();
  const bool s02 = std::all_of(runs.begin(), runs.end(),
                               [](const TwoAxisScan& r) { return r.s0_2_um.size() > 0; });
  if (!s02) m.s0_2_um.resize(0, 0);
  auto mats = [](TwoAxisScan& s) {
    return std::vector<Eigen::MatrixXd*>{&s.s0_1_um, &s.s1_1_um, &s.s1_2_um, &s.s2_1_um,
                                         &s.s2_2_um, &s.s3_1_um, &s.s3_2_um, &s.s4_1_um,
                                         &s.s4_2_um, &s.s0_2_um};
  };
  const auto dst = mats(m);
  for (std::size_t q = 1; q < runs.size(); ++q) {
    TwoAxisScan r = runs[q];
    require(
        r.x_mm.size() == m.x_mm.size() && r.y_mm.size() == m.y_mm.size() &&
            (r.x_mm - m.x_mm).cwiseAbs().maxCoeff() <=
                1e-9 * (1.0 + m.x_mm.cwiseAbs().maxCoeff()) &&
            (r.y_mm - m.y_mm).cwiseAbs().maxCoeff() <= 1e-9 * (1.0 + m.y_mm.cwiseAbs().maxCoeff()),
        "run " + std::to_string(q + 1) + " is on a different grid from run 1");
    const auto src = mats(r);
    for (std::size_t k = 0; k < dst.size(); ++k) {
      if (k == dst.size() - 1 && !s02) continue;
      require(src[k]->rows() == dst[k]->rows() && src[k]->cols() == dst[k]->cols(),
              "run " + std::to_string(q + 1) + " has readings of a different size from run 1");
      *dst[k] += *src[k];
    }
  }
  for (auto* p : dst)
    *p /= static_cast<double>(runs.size());
  return m;
}

DisplacementResiduals displacement_residuals_one_axis(const Eigen::VectorXd& x_mm,
                                                      const std::vector<OneAxisRun>& runs,
                                                      const DisplacementResidualOptions& o) {
  std::string why;
  require(o.is_valid(&why), why);
  require(!runs.empty(), "no runs");
  const Eigen::Index n = x_mm.size();
  require(n >= 2, "need at least 2 positions");
  const auto R = static_cast<int>(runs.size());
  for (int q = 0; q < R; ++q) {
    const auto& r = runs[static_cast<std::size_t>(q)];
    const std::string run = "run " + std::to_string(q + 1);
    require(r.s1_1_um.size() == n && r.s2_1_um.size() == n && r.s2_2_um.size() == n,
            run + ": every scan must have " + std::to_string(n) + " readings like x");
    require(r.s1_2_um.size() == 0 || r.s1_2_um.size() == n,
            run + ": s1_2 must have " + std::to_string(n) + " readings like x");
    check_finite(r.s1_1_um, run + " s1_1");
    check_finite(r.s2_1_um, run + " s2_1");
    check_finite(r.s2_2_um, run + " s2_2");
    check_finite(r.s1_2_um, run + " s1_2");
  }
  const OneAxisRun mean = mean_of_runs(runs);
  DisplacementResiduals out;
  out.runs = R;
  if (mean.s1_2_um.size() == n) {
    RedundancyFamily f;
    f.kind = RedundancyKind::workpiece_repeat;
    f.equation =
        "S1_2 - S1_1 = 0 up to one offset: Eq. (1) in both scans (the workpiece is not "
        "traversed); tests that m(x) repeats between the scans, as Eqs. (2), (3) assume";
    f.x_mm = x_mm;
    f.y_mm = Eigen::VectorXd::Zero(n);
    f.run = Eigen::VectorXi::Zero(n);
    f.channels.push_back(make_channel("s1_scan2 - s1_scan1", 1, 0, mean.s1_2_um - mean.s1_1_um,
                                      std::vector<int>(static_cast<std::size_t>(n), 0), 1,
                                      2.0 / R));
    finish_family(f, o);
    out.families.push_back(std::move(f));
  }
  if (R >= 2) {
    RedundancyFamily f;
    f.kind = RedundancyKind::repeated_runs;
    f.equation = "every reading repeated over " + std::to_string(R) +
                 " runs: reading minus its mean over the runs (Eqs. 1-3 R times)";
    const Eigen::Index L = n * R;
    f.x_mm.resize(L);
    f.y_mm = Eigen::VectorXd::Zero(L);
    f.run.resize(L);
    std::vector<int> group(static_cast<std::size_t>(L));
    for (int q = 0; q < R; ++q)
      for (Eigen::Index k = 0; k < n; ++k) {
        f.x_mm(q * n + k) = x_mm(k);
        f.run(q * n + k) = q + 1;
        group[static_cast<std::size_t>(q * n + k)] = static_cast<int>(k);
      }
    struct Src {
      const char* name;
      int sensor, scan;
      Eigen::VectorXd OneAxisRun::*v;
    };
    std::vector<Src> src = {{"s1_scan1", 1, 1, &OneAxisRun::s1_1_um},
                            {"s2_scan1", 2, 1, &OneAxisRun::s2_1_um},
                            {"s2_scan2", 2, 2, &OneAxisRun::s2_2_um}};
    if (mean.s1_2_um.size() == n) src.push_back({"s1_scan2", 1, 2, &OneAxisRun::s1_2_um});
    for (const auto& s : src) {
      Eigen::VectorXd v(L);
      for (int q = 0; q < R; ++q)
        v.segment(q * n, n) = runs[static_cast<std::size_t>(q)].*(s.v);
      f.channels.push_back(
          make_channel(s.name, s.sensor, s.scan, std::move(v), group, static_cast<int>(n), 1.0));
    }
    finish_family(f, o);
    out.families.push_back(std::move(f));
  }
  if (out.families.empty())
    out.note =
        "Eqs. (1)-(3) are exactly determined (3n readings for 3n identifiable values of w, m, r): "
        "nothing to test; record sensor 1 during scan 2 (s1_scan2_um) or repeat the measurement";
  finish(out, o);
  return out;
}

DisplacementResiduals displacement_residuals_two_axis(const std::vector<TwoAxisScan>& runs,
                                                      const DisplacementResidualOptions& o,
                                                      const Eigen::MatrixXd& time_order) {
  std::string why;
  require(o.is_valid(&why), why);
  require(!runs.empty(), "no runs");
  const Eigen::Index nx = runs.front().x_mm.size(), ny = runs.front().y_mm.size();
  require(nx >= 2 && ny >= 2, "the grid needs at least 2 x 2 points");
  const auto R = static_cast<int>(runs.size());
  for (int q = 0; q < R; ++q) {
    const auto& s = runs[static_cast<std::size_t>(q)];
    const std::pair<const char*, const Eigen::MatrixXd*> mats[] = {
        {"s0_1", &s.s0_1_um}, {"s1_1", &s.s1_1_um}, {"s1_2", &s.s1_2_um},
        {"s2_1", &s.s2_1_um}, {"s2_2", &s.s2_2_um}, {"s3_1", &s.s3_1_um},
        {"s3_2", &s.s3_2_um}, {"s4_1", &s.s4_1_um}, {"s4_2", &s.s4_2_um}};
    const std::string run = "run " + std::to_string(q + 1) + " ";
    for (const auto& [name, m] : mats) {
      require(m->rows() == nx && m->cols() == ny,
              run + name + " is " + std::to_string(m->rows()) + "x" + std::to_string(m->cols()) +
                  ", grid is " + std::to_string(nx) + "x" + std::to_string(ny));
      check_finite(*m, run + name);
    }
    require(s.s0_2_um.size() == 0 || (s.s0_2_um.rows() == nx && s.s0_2_um.cols() == ny),
            run + "s0_2 does not match the grid");
    check_finite(s.s0_2_um, run + "s0_2");
  }
  require(time_order.size() == 0 || (time_order.rows() == nx && time_order.cols() == ny),
          "time_order must be nx x ny like the grid");
  const TwoAxisScan mean = mean_of_runs(runs);
  // Time order of the grid points (flat index i + nx·j).
  const Eigen::Index P = nx * ny;
  std::vector<Eigen::Index> order(static_cast<std::size_t>(P));
  std::iota(order.begin(), order.end(), Eigen::Index{0});
  if (time_order.size()) {
    check_finite(time_order, "time_order");
    std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) {
      return time_order(a % nx, a / nx) < time_order(b % nx, b / nx);
    });
  }
  auto positions = [&](RedundancyFamily& f, int copies) {
    f.x_mm.resize(P * copies);
    f.y_mm.resize(P * copies);
    f.run.resize(P * copies);
    for (int q = 0; q < copies; ++q)
      for (Eigen::Index t = 0; t < P; ++t) {
        const Eigen::Index a = order[static_cast<std::size_t>(t)];
        f.x_mm(q * P + t) = mean.x_mm(a % nx);
        f.y_mm(q * P + t) = mean.y_mm(a / nx);
        f.run(q * P + t) = copies > 1 ? q + 1 : 0;
      }
  };
  auto in_time_order = [&](const Eigen::MatrixXd& m) {
    Eigen::VectorXd v(P);
    for (Eigen::Index t = 0; t < P; ++t) {
      const Eigen::Index a = order[static_cast<std::size_t>(t)];
      v(t) = m(a % nx, a / nx);
    }
    return v;
  };
  DisplacementResiduals out;
  out.runs = R;
  {
    RedundancyFamily f;
    f.kind = RedundancyKind::reference_pieces;
    f.equation =
        "S k_2 - S k_1 = r k(x + d) - r k(x) (Eqs. 11-19, as Eq. 4) on every row y_j for k = 1, "
        "2 and every column x_i for k = 3, 4: the reference pieces are functions of one "
        "coordinate";
    positions(f, 1);
    std::vector<int> by_x(static_cast<std::size_t>(P)), by_y(static_cast<std::size_t>(P));
    for (Eigen::Index t = 0; t < P; ++t) {
      by_x[static_cast<std::size_t>(t)] = static_cast<int>(order[static_cast<std::size_t>(t)] % nx);
      by_y[static_cast<std::size_t>(t)] = static_cast<int>(order[static_cast<std::size_t>(t)] / nx);
    }
    const double c = 2.0 / R;
    f.channels.push_back(make_channel("s1_scan2 - s1_scan1", 1, 0,
                                      in_time_order(mean.s1_2_um - mean.s1_1_um), by_x,
                                      static_cast<int>(nx), c));
    f.channels.push_back(make_channel("s2_scan2 - s2_scan1", 2, 0,
                                      in_time_order(mean.s2_2_um - mean.s2_1_um), by_x,
                                      static_cast<int>(nx), c));
    f.channels.push_back(make_channel("s3_scan2 - s3_scan1", 3, 0,
                                      in_time_order(mean.s3_2_um - mean.s3_1_um), by_y,
                                      static_cast<int>(ny), c));
    f.channels.push_back(make_channel("s4_scan2 - s4_scan1", 4, 0,
                                      in_time_order(mean.s4_2_um - mean.s4_1_um), by_y,
                                      static_cast<int>(ny), c));
    finish_family(f, o);
    out.families.push_back(std::move(f));
  }
  if (mean.s0_2_um.size() == P) {
    RedundancyFamily f;
    f.kind = RedundancyKind::workpiece_repeat;
    f.equation =
        "S0_2 - S0_1 = 0 up to one offset: Eq. (10) in both scans (the workpiece is not "
        "traversed); tests that m_w repeats between the scans";
    positions(f, 1);
    f.channels.push_back(
        make_channel("s0_scan2 - s0_scan1", 0, 0, in_time_order(mean.s0_2_um - mean.s0_1_um),
                     std::vector<int>(static_cast<std::size_t>(P), 0), 1, 2.0 / R));
    finish_family(f, o);
    out.families.push_back(std::move(f));
  }
  if (R >= 2) {
    RedundancyFamily f;
    f.kind = RedundancyKind::repeated_runs;
    f.equation = "every reading repeated over " + std::to_string(R) +
                 " runs: reading minus its mean over the runs (Eqs. 10-19 R times)";
    positions(f, R);
    std::vector<int> group(static_cast<std::size_t>(P * R));
    for (int q = 0; q < R; ++q)
      for (Eigen::Index t = 0; t < P; ++t)
        group[static_cast<std::size_t>(q * P + t)] =
            static_cast<int>(order[static_cast<std::size_t>(t)]);
    struct Src {
      const char* name;
      int sensor, scan;
      Eigen::MatrixXd TwoAxisScan::*m;
    };
    std::vector<Src> src = {
        {"s0_scan1", 0, 1, &TwoAxisScan::s0_1_um}, {"s1_scan1", 1, 1, &TwoAxisScan::s1_1_um},
        {"s1_scan2", 1, 2, &TwoAxisScan::s1_2_um}, {"s2_scan1", 2, 1, &TwoAxisScan::s2_1_um},
        {"s2_scan2", 2, 2, &TwoAxisScan::s2_2_um}, {"s3_scan1", 3, 1, &TwoAxisScan::s3_1_um},
        {"s3_scan2", 3, 2, &TwoAxisScan::s3_2_um}, {"s4_scan1", 4, 1, &TwoAxisScan::s4_1_um},
        {"s4_scan2", 4, 2, &TwoAxisScan::s4_2_um}};
    if (mean.s0_2_um.size() == P) src.push_back({"s0_scan2", 0, 2, &TwoAxisScan::s0_2_um});
    for (const auto& s : src) {
      Eigen::VectorXd v(P * R);
      for (int q = 0; q < R; ++q)
        v.segment(q * P, P) = in_time_order(runs[static_cast<std::size_t>(q)].*(s.m));
      f.channels.push_back(
          make_channel(s.name, s.sensor, s.scan, std::move(v), group, static_cast<int>(P), 1.0));
    }
    finish_family(f, o);
    out.families.push_back(std::move(f));
  }
  finish(out, o);
  return out;
}

}  // namespace errsep::core
