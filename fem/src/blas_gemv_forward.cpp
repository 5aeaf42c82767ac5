// GEMM with one column forwarded to GEMV, and TRSM with one right-hand side to TRSV.
//
// MUMPS 5.5's solve phase applies each front of the factor to the right-hand side with
// xGEMM, also for a single right-hand side (N = 1). OpenBLAS 0.3.21 (Debian 12) runs such a
// product as a full matrix product: it first copies ("packs") the factor's block into its
// working layout, which for one column costs as much as the product itself. Measured with
// perf on the Cranium 60 deg Z-plasty (17.7k DOF, conjugate gradients preconditioned by the
// single-precision factor): 27 % of the whole finite-strain solve was MUMPS's solve phase,
// most of it in sgemm's packing and kernel. OpenBLAS 0.3.27 forwards such calls to xGEMV
// itself (its GEMM_GEMV_FORWARD option); this file does the same for the BLAS Debian 12 has:
// sgemm_ and dgemm_ defined here take precedence over the shared library's for the libraries
// this program loads (the executable's dynamic symbols are searched first), handle N = 1 with
// xGEMV (the same sums, without the copy) and pass every other call to the library's own
// xGEMM, found with dlsym(RTLD_NEXT). The solve phase's triangular solves of a front's pivot
// block go through xTRSM with one right-hand side in the same way (OpenBLAS packs the triangle
// first: dtrsm's packing was 1.2 % and dtrsm 5 % of the Cranium whole-face ellipse's closure,
// double precision); they are forwarded to xTRSV.
//
// The arguments follow the reference BLAS (Fortran, by reference, LP64 integers). Fortran
// callers pass the lengths of the two character arguments after them; they are not used
// (the characters are one letter) and not passed on, as C callers of BLAS do.

#include <dlfcn.h>

#include <cstdlib>

namespace {

template <class Real>
using Gemm = void (*)(const char*, const char*, const int*, const int*, const int*, const Real*,
                      const Real*, const int*, const Real*, const int*, const Real*, Real*,
                      const int*);

template <class Real>
using Gemv = void (*)(const char*, const int*, const int*, const Real*, const Real*, const int*,
                      const Real*, const int*, const Real*, Real*, const int*);

// The BLAS the solvers link (libblas.so.3), looked up at the first call: RTLD_NEXT skips the
// definitions in this file.
template <class F>
F blas(const char* name) {
  void* f = dlsym(RTLD_NEXT, name);
  if (!f) std::abort();  // no BLAS in the process: cannot happen, MUMPS links it
  return reinterpret_cast<F>(f);
}

bool transposed(const char* t) { return *t == 'T' || *t == 't' || *t == 'C' || *t == 'c'; }

// C (m x 1) = alpha op(A) op(B) + beta C with op(A) m x k, op(B) k x 1, as
// y = alpha op(A) x + beta y. Returns false where xGEMV's quick returns differ from xGEMM's
// (m or k zero: GEMM still scales C by beta).
template <class Real>
bool gemv_instead(Gemv<Real> gemv, const char* transa, const char* transb, const int* m, const int* n,
                  const int* k, const Real* alpha, const Real* a, const int* lda, const Real* b,
                  const int* ldb, const Real* beta, Real* c) {
  if (*n != 1 || *m <= 0 || *k <= 0) return false;
  const int one = 1;
  // op(B)'s one column: B's column (stride 1) or, transposed, B's first row (stride ldb).
  const int incx = transposed(transb) ? *ldb : 1;
  if (transposed(transa))  // A is k x m
    gemv("T", k, m, alpha, a, lda, b, &incx, beta, c, &one);
  else  // A is m x k
    gemv("N", m, k, alpha, a, lda, b, &incx, beta, c, &one);
  return true;
}

template <class Real>
using Trsm = void (*)(const char*, const char*, const char*, const char*, const int*, const int*,
                      const Real*, const Real*, const int*, Real*, const int*);

template <class Real>
using Trsv = void (*)(const char*, const char*, const char*, const int*, const Real*, const int*,
                      Real*, const int*);

template <class Real>
using Scal = void (*)(const int*, const Real*, Real*, const int*);

// op(A) X = alpha B (side L, B m x 1) or X op(A) = alpha B (side R, B 1 x n) as a TRSV on B's one
// column or row, after scaling it by alpha. Returns false for everything else, and for alpha = 0
// (TRSM then sets B to zero, which scaling would not do to an infinity or a NaN) and empty B.
template <class Real>
bool trsv_instead(Trsv<Real> trsv, Scal<Real> scal, const char* side, const char* uplo,
                  const char* transa, const char* diag, const int* m, const int* n,
                  const Real* alpha, const Real* a, const int* lda, Real* b, const int* ldb) {
  if (*m <= 0 || *n <= 0 || *alpha == Real(0)) return false;
  const bool left = *side == 'L' || *side == 'l';
  if (left ? *n != 1 : *m != 1) return false;
  const int len = left ? *m : *n, inc = left ? 1 : *ldb;
  if (*alpha != Real(1)) scal(&len, alpha, b, &inc);
  // x op(A) = b is op(A)^T x^T = b^T: the other transposition.
  const char* trans = left ? transa : (transposed(transa) ? "N" : "T");
  trsv(uplo, trans, diag, &len, a, lda, b, &inc);
  return true;
}

// The BLAS names of one precision.
template <class Real>
struct Names;
template <>
struct Names<float> {
  static constexpr const char *gemm = "sgemm_", *gemv = "sgemv_", *trsm = "strsm_", *trsv = "strsv_",
                             *scal = "sscal_";
};
template <>
struct Names<double> {
  static constexpr const char *gemm = "dgemm_", *gemv = "dgemv_", *trsm = "dtrsm_", *trsv = "dtrsv_",
                             *scal = "dscal_";
};

// xGEMM and xTRSM of either precision: the forward above, or the library's own.
template <class Real>
void gemm(const char* transa, const char* transb, const int* m, const int* n, const int* k,
          const Real* alpha, const Real* a, const int* lda, const Real* b, const int* ldb,
          const Real* beta, Real* c, const int* ldc) {
  static const Gemm<Real> next = blas<Gemm<Real>>(Names<Real>::gemm);
  static const Gemv<Real> gemv = blas<Gemv<Real>>(Names<Real>::gemv);
  if (!gemv_instead(gemv, transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c))
    next(transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
}

template <class Real>
void trsm(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
          const int* n, const Real* alpha, const Real* a, const int* lda, Real* b, const int* ldb) {
  static const Trsm<Real> next = blas<Trsm<Real>>(Names<Real>::trsm);
  static const Trsv<Real> trsv = blas<Trsv<Real>>(Names<Real>::trsv);
  static const Scal<Real> scal = blas<Scal<Real>>(Names<Real>::scal);
  if (!trsv_instead(trsv, scal, side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb))
    next(side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb);
}

}  // namespace

extern "C" {

void strsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const float* alpha, const float* a, const int* lda, float* b, const int* ldb) {
  trsm(side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb);
}

void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb) {
  trsm(side, uplo, transa, diag, m, n, alpha, a, lda, b, ldb);
}

void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const float* alpha, const float* a, const int* lda, const float* b, const int* ldb,
            const float* beta, float* c, const int* ldc) {
  gemm(transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
}

void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc) {
  gemm(transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
}

}  // extern "C"

namespace caps::fem::detail {
// Referenced by make_direct_solver() so that the linker takes this file from the static library.
bool gemv_forwarding_linked() { return true; }
}  // namespace caps::fem::detail
