#pragma once
// Included once by each solver benchmark: OpenBLAS on the CPU's own kernels before the first
// benchmark, as the caps program runs (fem/blas.hpp), and the kernels named in the output's
// context.
#include <benchmark/benchmark.h>

#include "caps/fem/blas.hpp"

inline const bool kBlasKernels = [] {
  caps::fem::use_the_cpus_blas_kernels();
  benchmark::AddCustomContext("blas_kernels", caps::fem::blas_core());
  return true;
}();
