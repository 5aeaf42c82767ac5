// Linked into every test program of the modules that solve (fem and above): OpenBLAS on the
// CPU's own kernels before any test runs, as the caps program and the Python module run
// (fem/blas.hpp), so that a test comparing an in-process answer with the caps program's compares
// the same arithmetic.
#include "caps/core/crash_report.hpp"
#include "caps/fem/blas.hpp"

namespace {

const bool kBlasKernels = [] {
  caps::fem::use_the_cpus_blas_kernels();
  // A fault says where (core/crash_report.hpp): two SIGFPEs under a loaded full run, never alone.
  caps::install_crash_report();
  return true;
}();

}  // namespace
