// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Which fixed-point kernel runs on this build and CPU (AVX2 detection on x86-64, NEON on aarch64, scalar otherwise).
#include "tofmat/core/fixed_kernel.hpp"

namespace tofmat {

bool cpu_has_avx2() {
#if defined(__x86_64__)
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
#else
  return false;
#endif
}

const char* best_pixel_kernel() {
#if defined(__aarch64__)
  return "neon";
#else
  return cpu_has_avx2() ? "avx2" : "scalar";
#endif
}

}  // namespace tofmat
