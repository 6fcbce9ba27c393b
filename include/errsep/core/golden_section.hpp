#pragma once
// Golden-section search for the minimum of a function of one variable on [lo, hi] (unimodal
// there): each step keeps the part of the bracket that holds the smaller of its two interior
// values and evaluates the function once.  Used for a time constant fitted by least squares
// (sequence_refine.cpp and displacement_refine.cpp: a thermal drift's τ on log τ).  Pure
// computation, no allocation.
#include <cmath>

namespace errsep::core {

/// The midpoint of the final bracket, after at most `max_steps` steps or when the bracket is
/// narrower than `tolerance`.  f is called 2 + steps times.
template <class F>
double golden_section_minimum(F&& f, double lo, double hi, double tolerance, int max_steps = 60) {
  const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
  double a = hi - phi * (hi - lo), c = lo + phi * (hi - lo);
  double fa = f(a), fc = f(c);
  for (int it = 0; it < max_steps && hi - lo > tolerance; ++it) {
    if (fa < fc) {
      hi = c;
      c = a;
      fc = fa;
      a = hi - phi * (hi - lo);
      fa = f(a);
    } else {
      lo = a;
      a = c;
      fa = fc;
      c = lo + phi * (hi - lo);
      fc = f(c);
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace errsep::core
