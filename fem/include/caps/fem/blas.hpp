#pragma once
// The dense kernels under the sparse direct solvers. MUMPS and CHOLMOD factorize their fronts and
// supernodes with the system's BLAS (Debian's libblas.so.3, OpenBLAS by the project's setup), and
// OpenBLAS picks its kernels for the CPU when it loads. A CPU newer than the OpenBLAS build
// knows (OpenBLAS 0.3.21, Debian 12, on an Intel Emerald Rapids: family 6, model 207) gets its
// generic SSE3 kernels (Prescott), and every factorization takes about twice as long as with the
// AVX2 or AVX-512 kernels the CPU runs (docs/benchmarks.md, "The BLAS kernels").

#include <string>

namespace caps::fem {

/// The kernels OpenBLAS chose in this process ("Prescott", "Haswell", "SkylakeX", ...); "" when
/// the BLAS is not OpenBLAS.
std::string blas_core();

/// The OPENBLAS_CORETYPE this process should have been started with: "SkylakeX" (AVX-512 F, BW,
/// DQ, VL) or "Haswell" (AVX2 and FMA) when OpenBLAS chose kernels older than the CPU's (a CPU it
/// does not know); "" when its choice stands, OPENBLAS_CORETYPE is set already, or the BLAS is
/// not OpenBLAS.
std::string blas_core_to_force();

/// Switches OpenBLAS to blas_core_to_force()'s kernels, if any: sets OPENBLAS_CORETYPE (for this
/// process and the programs it starts, such as ccx) and has OpenBLAS choose again, as it does
/// when it loads (gotoblas_dynamic_quit() and gotoblas_dynamic_init(), which a DYNAMIC_ARCH
/// build exports). Call it before any BLAS work and before other threads start (the caps
/// program's main(), the Python module's import). Returns the kernels now in use when it
/// switched, "" otherwise.
std::string use_the_cpus_blas_kernels();

/// While alive, the BLAS under the direct solvers runs on `threads` threads (OpenBLAS, when it
/// is the BLAS loaded; any other BLAS is left alone; 0 leaves it as configured). The count it
/// had is restored when the last of the guards alive in the process ends; guards of concurrent
/// solves share the first one's count. fem::solve() holds one for its factorizations; a caller
/// that solves in several threads at once holds one around them all, so that OpenBLAS's count
/// is never changed (openblas_set_num_threads()) while another thread is inside a BLAS call
/// (OpenBLAS's worker threads spin (sched_yield) after each call and take a core from TBB's
/// assembly; a sparse factorization of skin meshes gains little from them: docs/benchmarks.md).
class BlasThreads {
 public:
  explicit BlasThreads(int threads);
  ~BlasThreads();
  BlasThreads(const BlasThreads&) = delete;
  BlasThreads& operator=(const BlasThreads&) = delete;

 private:
  bool active_ = false;
};

}  // namespace caps::fem
