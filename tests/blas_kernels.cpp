// Linked into every test program of the modules that solve (fem and above): OpenBLAS on the
// CPU's own kernels before any test runs, as the caps program and the Python module run
// (fem/blas.hpp), so that a test comparing an in-process answer with the caps program's compares
// the same arithmetic.
#include "caps/fem/blas.hpp"

namespace {

const bool kBlasKernels = [] {
  caps::fem::use_the_cpus_blas_kernels();
  return true;
}();

}  // namespace
