// Which implementation of a fixed-point kernel runs: the build's best (NEON
// on aarch64, scalar elsewhere), or the scalar one (the definition the NEON
// kernels are checked against, bit for bit).
#pragma once

namespace tofmat {

enum class FixedKernel { kBest, kScalar };

}  // namespace tofmat
