#pragma once
// A random sparse matrix shaped like the four-sensor systems: band rows over m unknowns plus a
// dense border of k columns (every third row touches each border column).  For tests of the
// banded solvers against dense references.
#include <Eigen/SparseCore>
#include <algorithm>
#include <cstdlib>
#include <vector>

namespace errsep::test {

inline Eigen::SparseMatrix<double> random_banded(int rows, int m, int k, int width, unsigned seed) {
  std::srand(seed);
  auto rnd = [] { return 2.0 * std::rand() / RAND_MAX - 1.0; };
  std::vector<Eigen::Triplet<double>> t;
  for (int r = 0; r < rows; ++r) {
    const int c0 = (r * (m - width)) / std::max(1, rows - 1);
    for (int c = c0; c < c0 + width; ++c)
      t.emplace_back(r, c, rnd());
    for (int c = 0; c < k; ++c)
      if (r % 3 == c % 3) t.emplace_back(r, m + c, rnd());
  }
  Eigen::SparseMatrix<double> A(rows, m + k);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

}  // namespace errsep::test
