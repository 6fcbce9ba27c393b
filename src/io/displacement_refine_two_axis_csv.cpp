#include "errsep/io/displacement_refine_two_axis_csv.hpp"

#include <cmath>
#include <limits>

#include "displacement_refine_account.hpp"

namespace errsep::io {

CsvTable displacement_refine_two_axis_csv(const core::DisplacementRefineResult& r,
                                          const std::string& plan) {
  CsvTable t = detail::displacement_refine_account(
      "two-axis displacement method (Haramiishi et al. 2024, Eqs. 10-19)", r.applied_any(),
      r.not_identifiable);
  t.set_meta("plan", plan);
  t.set_meta("sigma_scale", std::to_string(r.sigma_scale));
  t.columns.push_back("m_w_change_rms_um");
  t.columns.push_back("m_w_error_without_rms_um");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t s = 0; s < r.steps.size(); ++s) {
    const auto& st = r.steps[s];
    const std::string key = "step" + std::to_string(s + 1);
    t.set_meta(key + "_effect", st.effect);
    t.set_meta(key + "_decision", st.applied ? "applied" : "detected, not applied");
    t.set_meta(key + "_line", st.line);
    const auto* w = st.decision.quantity("w");
    const auto* m = st.decision.quantity("m_w");
    // What the step adds to the refined u(w): applied, its covariance; left out, its fitted size
    // and that size's scatter (core/displacement_refine.cpp).
    const double added = !w           ? nan
                         : st.applied ? w->rms_added_u
                                      : std::hypot(w->rms_change, w->rms_added_u);
    for (Eigen::Index j = 0; j < st.value.size(); ++j) {
      t.set_meta(key + "_parameter" + std::to_string(j), st.names[static_cast<std::size_t>(j)]);
      t.rows.push_back({static_cast<double>(s + 1), static_cast<double>(j), st.value(j), st.u(j),
                        st.F, st.p_value, st.applied ? 1.0 : 0.0, w ? w->rms_change : nan,
                        w ? w->rms_bias : nan, w ? w->rms_added_u : nan, added,
                        m ? m->rms_change : nan, m ? m->rms_bias : nan});
    }
  }
  t.set_meta("steps", std::to_string(r.steps.size()));
  return t;
}

}  // namespace errsep::io
