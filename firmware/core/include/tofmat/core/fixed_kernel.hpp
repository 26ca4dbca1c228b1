// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Which implementation of a fixed-point kernel runs: the best one for this
// build and CPU (NEON on aarch64, AVX2 on an x86-64 CPU that has it, scalar
// otherwise), or the scalar one (the definition the vector kernels are
// checked against, bit for bit).
#pragma once

namespace tofmat {

enum class FixedKernel { kBest, kScalar };

// True on x86-64 when the CPU reports AVX2 (checked once); false elsewhere.
bool cpu_has_avx2();

// The name of the kernel kBest selects for the decode and per-pixel
// classification on this machine ("neon", "avx2" or "scalar").
const char* best_pixel_kernel();

}  // namespace tofmat
