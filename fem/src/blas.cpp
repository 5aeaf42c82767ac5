#include "caps/fem/blas.hpp"

#include <dlfcn.h>
#include <stdlib.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <string_view>

namespace caps::fem {

std::string blas_core() {
  using CoreName = char* (*)();
  const auto name = reinterpret_cast<CoreName>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  const char* core = name ? name() : nullptr;
  return core ? std::string(core) : std::string();
}

std::string blas_core_to_force() {
  if (std::getenv("OPENBLAS_CORETYPE")) return {};
  const std::string core = blas_core();
  // OpenBLAS's kernels for CPUs without AVX2 (gotoblas_corename()'s spelling): what it falls
  // back to on a CPU it does not know.
  constexpr std::array<std::string_view, 16> kOlder{
      "Katmai",       "Coppermine", "Northwood",  "Prescott",  "Banias",      "Atom",
      "Core2",        "Penryn",     "Dunnington", "Nehalem",   "Sandybridge", "Opteron",
      "Opteron_SSE3", "Barcelona",  "Bulldozer",  "Piledriver"};
  if (std::find(kOlder.begin(), kOlder.end(), core) == kOlder.end()) return {};
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
  return {};
}

std::string use_the_cpus_blas_kernels() {
  const std::string core = blas_core_to_force();
  if (core.empty()) return {};
  using Call = void (*)();
  const auto quit = reinterpret_cast<Call>(dlsym(RTLD_DEFAULT, "gotoblas_dynamic_quit"));
  const auto init = reinterpret_cast<Call>(dlsym(RTLD_DEFAULT, "gotoblas_dynamic_init"));
  if (!quit || !init) return {};  // not a DYNAMIC_ARCH build: its kernels are fixed
  ::setenv("OPENBLAS_CORETYPE", core.c_str(), 1);
  quit();
  init();
  return blas_core();
}

}  // namespace caps::fem
