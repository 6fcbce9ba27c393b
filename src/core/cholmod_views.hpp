#pragma once
// Views of Eigen storage as CHOLMOD objects, without copying: the two files that call CHOLMOD
// directly (tikhonov_solver.cpp, sparse_least_squares.cpp) share them.  Private to src/core.
#include <cholmod.h>

#include <Eigen/SparseCore>

namespace errsep::core::detail {

/// An Eigen column-major compressed sparse matrix as an unsymmetric cholmod_sparse (stype 0:
/// CHOLMOD then factors M·Mᵀ).
inline cholmod_sparse view(const Eigen::SparseMatrix<double>& M) {
  cholmod_sparse s{};
  s.nrow = static_cast<size_t>(M.rows());
  s.ncol = static_cast<size_t>(M.cols());
  s.nzmax = static_cast<size_t>(M.nonZeros());
  s.p = const_cast<int*>(M.outerIndexPtr());
  s.i = const_cast<int*>(M.innerIndexPtr());
  s.x = const_cast<double*>(M.valuePtr());
  s.stype = 0;
  s.itype = CHOLMOD_INT;
  s.xtype = CHOLMOD_REAL;
  s.dtype = CHOLMOD_DOUBLE;
  s.sorted = 1;
  s.packed = 1;
  return s;
}

/// A column-major rows × cols array as a cholmod_dense.
inline cholmod_dense view(const double* v, Eigen::Index rows, Eigen::Index cols) {
  cholmod_dense d{};
  d.nrow = d.d = static_cast<size_t>(rows);
  d.ncol = static_cast<size_t>(cols);
  d.nzmax = d.nrow * d.ncol;
  d.x = const_cast<double*>(v);
  d.xtype = CHOLMOD_REAL;
  d.dtype = CHOLMOD_DOUBLE;
  return d;
}

}  // namespace errsep::core::detail
