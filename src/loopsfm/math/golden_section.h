#pragma once
// One-dimensional minimisation by golden-section search.

namespace loopsfm {

// Minimum of function(x) on [lo, hi] by golden-section search, to a bracket of tol: exact
// for a function with one minimum in the interval (unimodal), a local minimum otherwise.
template <typename Function>
double GoldenSectionMinimum(const Function& function, double lo, double hi, double tol) {
  constexpr double kRatio = 0.38196601125010515;  // (3 - sqrt(5)) / 2
  double a = lo, b = hi;
  double x1 = a + kRatio * (b - a), x2 = b - kRatio * (b - a);
  double f1 = function(x1), f2 = function(x2);
  while (b - a > tol) {
    if (f1 <= f2) {
      b = x2;
      x2 = x1;
      f2 = f1;
      x1 = a + kRatio * (b - a);
      f1 = function(x1);
    } else {
      a = x1;
      x1 = x2;
      f1 = f2;
      x2 = b - kRatio * (b - a);
      f2 = function(x2);
    }
  }
  return f1 <= f2 ? x1 : x2;
}

}  // namespace loopsfm
