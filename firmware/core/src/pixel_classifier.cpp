// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// PixelClassifier: the table rearranged bin-major at construction, the scalar per-pixel kernel and the kernel dispatch.
#include "tofmat/core/pixel_classifier.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tofmat {

namespace {

bool valid_at(const CompactTable& c, std::size_t k, std::size_t e) {
  const std::uint8_t* m = c.validity(k);
  return m == nullptr || ((m[e / 8] >> (e % 8)) & 1) != 0;
}

// Packs two int16 into the low and high halves of an int32 (as madd_epi16 reads them).
std::int32_t pack(std::int32_t lo, std::int32_t hi) {
  return static_cast<std::int32_t>((static_cast<std::uint32_t>(lo) & 0xFFFFu) | (static_cast<std::uint32_t>(hi) << 16));
}
std::int32_t low16(std::int32_t v) { return static_cast<std::int16_t>(static_cast<std::uint32_t>(v) & 0xFFFFu); }
std::int32_t high16(std::int32_t v) { return static_cast<std::int16_t>(static_cast<std::uint32_t>(v) >> 16); }

}  // namespace

PixelClassifier::PixelClassifier(const CompactTable& c, const BinSpec& bins)
    : n_candidates_(c.n_candidates()), binning_(FixedBinning::from(bins)) {
  if (c.n_rows() != 2) throw std::invalid_argument("per-pixel classification needs the two-row Kinect v2 table");
  if (c.n_candidates() == 0 || c.n_candidates() > 254) {
    throw std::invalid_argument("per-pixel classification takes 1 to 254 candidates");
  }
  if (bins.count != c.n_bins()) throw std::invalid_argument("bins do not match the table's");
  int exp2 = 0;
  if (std::frexp(c.step_mm(), &exp2) != 0.5) throw std::invalid_argument("table step is not a power of two");
  Layout& t = layout_;
  t.shift = kDepthFracBits + (exp2 - 1);  // Q16 mm -> steps: >> (16 + log2 step)
  if (t.shift < 1 || t.shift > 30) throw std::invalid_argument("table step out of range");
  t.bins = c.n_bins();
  t.slots = (n_candidates_ + kSlotBlock - 1) / kSlotBlock * kSlotBlock;
  const std::size_t n = t.slots * t.bins;
  t.pairs.assign(n, 0);
  t.elem_mask.assign(n, 0);
  t.doubled.assign(n, 0);
  t.absent.assign(n, 0x7FFFFFFF);
  // Slot of each rank (rank = candidate index; ranks >= candidates pad).
  // With four blocks the AVX2 kernel packs its four compare masks to bytes
  // (packs_epi32, packs_epi16: per 128-bit half) and reads them with one
  // movemask: bit j comes from block (j / 4) % 4, lane j % 4 + 4 (j / 16).
  // Storing rank j there makes the mask's lowest set bit the rank itself.
  t.slot_of.resize(t.slots);
  for (std::size_t j = 0; j < t.slots; ++j) {
    t.slot_of[j] = static_cast<std::uint8_t>(t.slots == 4 * kSlotBlock ? 8 * ((j / 4) % 4) + j % 4 + 4 * (j / 16) : j);
  }
  for (std::uint32_t b = 0; b < t.bins; ++b) {
    const std::size_t row = b * t.slots;
    for (std::size_t k = 0; k < n_candidates_; ++k) {
      const std::size_t e0 = b, e1 = c.padded_bins() + b, s = row + t.slot_of[k];
      const bool v0 = valid_at(c, k, e0), v1 = valid_at(c, k, e1);
      t.pairs[s] = pack(c.values(k)[e0], c.values(k)[e1]);
      t.elem_mask[s] = pack(v0 ? 0xFFFF : 0, v1 ? 0xFFFF : 0);
      t.doubled[s] = v0 != v1 ? 1 : 0;
      t.absent[s] = v0 || v1 ? 0 : 0x7FFFFFFF;
      t.one_valid = t.one_valid || v0 != v1;
    }
    // A slot without values (padding, or a candidate missing at this bin)
    // takes a copy of the lowest-ranked candidate that has them, if that one
    // ranks lower: a tie with it always goes to it, so the copy never wins,
    // and the kernel needs no absent mask at this bin.
    std::size_t first = 0;
    while (first < n_candidates_ && t.absent[row + t.slot_of[first]] != 0) ++first;
    t.needs_absent.push_back(0);
    for (std::size_t k = 0; k < t.slots; ++k) {
      const std::size_t s = row + t.slot_of[k];
      if (t.absent[s] == 0) continue;
      if (first < n_candidates_ && first < k) {
        const std::size_t from = row + t.slot_of[first];
        t.pairs[s] = t.pairs[from];
        t.elem_mask[s] = t.elem_mask[from];
        t.doubled[s] = t.doubled[from];
        t.absent[s] = 0;
      } else {
        t.needs_absent.back() = 1;
      }
    }
  }
}

void quantise_features_scalar(const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift,
                              std::int32_t* q) {
  const std::int32_t half = std::int32_t{1} << (shift - 1);
  const auto steps = [&](std::int32_t f) {
    const std::int32_t c = std::clamp(f, -(std::int32_t{1} << 30), std::int32_t{1} << 30);  // + half < 2^31
    return std::clamp((c + half) >> shift, -32767, 32767);
  };
  for (std::size_t i = 0; i < n; ++i) q[i] = pack(steps(f0[i]), steps(f1[i]));
}

std::size_t classify_pixels_scalar(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                   std::size_t n, std::uint8_t* labels) {
  std::size_t classified = 0;
  for (std::size_t i = 0; i < n; ++i) {
    labels[i] = PixelClassifier::kUnclassified;
    if (bin[i] < 0) continue;
    const std::int32_t q0 = low16(q[i]), q1 = high16(q[i]);
    const std::size_t base = static_cast<std::size_t>(bin[i]) * t.slots;
    std::int32_t best = 0x7FFFFFFF;
    for (std::size_t k = 0; k < t.slots; ++k) {  // in rank order: ties go to the lower rank
      const std::size_t s = base + t.slot_of[k];
      if (t.absent[s] != 0) continue;
      const std::int32_t m = t.elem_mask[s];
      const std::int32_t d0 = low16(m) ? std::clamp(q0 - low16(t.pairs[s]), -32767, 32767) : 0;
      const std::int32_t d1 = high16(m) ? std::clamp(q1 - high16(t.pairs[s]), -32767, 32767) : 0;
      const std::int32_t sum = (d0 * d0 + d1 * d1) << t.doubled[s];  // <= 2 * 32767^2 < 2^31
      if (sum < best) {
        best = sum;
        labels[i] = static_cast<std::uint8_t>(k);
      }
    }
    classified += labels[i] != PixelClassifier::kUnclassified;
  }
  return classified;
}

namespace {

void quantise(FixedKernel kernel, const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift,
              std::int32_t* q) {
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return quantise_features_neon(f0, f1, n, shift, q);
#elif defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return quantise_features_avx2(f0, f1, n, shift, q);
#endif
  (void)kernel;
  quantise_features_scalar(f0, f1, n, shift, q);
}

std::size_t run_kernel(FixedKernel kernel, const PixelClassifier::Layout& t, const std::int32_t* bin,
                       const std::int32_t* q, std::size_t n, std::uint8_t* labels) {
#if defined(__aarch64__)
  if (kernel == FixedKernel::kBest) return classify_pixels_neon(t, bin, q, n, labels);
#elif defined(__x86_64__)
  if (kernel == FixedKernel::kBest && cpu_has_avx2()) return classify_pixels_avx2(t, bin, q, n, labels);
#endif
  (void)kernel;
  return classify_pixels_scalar(t, bin, q, n, labels);
}

}  // namespace

// Bins (computed here when `bin` is null) and labels of up to kChunk pixels.
std::size_t PixelClassifier::classify_chunk(const std::int32_t* depth_q8, const std::uint8_t* flags,
                                            const std::int32_t* bin, const std::int32_t* f0, const std::int32_t* f1,
                                            std::size_t n, std::uint8_t* labels, FixedKernel kernel) const {
  std::int32_t own_bin[kChunk], q[kChunk];
  if (bin == nullptr) {
    bin_indices(kernel, depth_q8, flags, n, binning_, own_bin);
    bin = own_bin;
  }
  quantise(kernel, f0, f1, n, layout_.shift, q);
  return run_kernel(kernel, layout_, bin, q, n, labels);
}

std::size_t PixelClassifier::classify(const std::int32_t* bin, const std::int32_t* f0, const std::int32_t* f1,
                                      std::size_t n, std::uint8_t* labels, FixedKernel kernel) const {
  std::size_t classified = 0;
  for (std::size_t at = 0; at < n; at += kChunk) {
    const std::size_t m = std::min(kChunk, n - at);
    classified += classify_chunk(nullptr, nullptr, bin + at, f0 + at, f1 + at, m, labels + at, kernel);
  }
  return classified;
}

std::size_t PixelClassifier::classify_range(const std::int32_t* combined_q8, const std::uint8_t* flags,
                                            const std::int32_t* f0, const std::int32_t* f1, std::size_t n,
                                            std::uint8_t* labels, FixedKernel kernel) const {
  std::size_t classified = 0;
  for (std::size_t at = 0; at < n; at += kChunk) {
    const std::size_t m = std::min(kChunk, n - at);
    classified += classify_chunk(combined_q8 + at, flags + at, nullptr, f0 + at, f1 + at, m, labels + at, kernel);
  }
  return classified;
}

std::size_t PixelClassifier::classify(const FixedDecodedFrame& f, std::uint8_t* labels, FixedKernel kernel) const {
  if (f.combined_q8.size() != f.pixels || f.flags.size() != f.pixels || f.features_q16[0].size() != f.pixels ||
      f.features_q16[1].size() != f.pixels) {
    throw std::invalid_argument("decoded frame's arrays do not match its pixel count");
  }
  return classify_range(f.combined_q8.data(), f.flags.data(), f.features_q16[0].data(), f.features_q16[1].data(),
                        f.pixels, labels, kernel);
}

std::size_t PixelClassifier::classify_frame(const std::int16_t* raw, const FixedDecodeTables& tables,
                                            std::uint8_t* labels, const DecodeOptions& options,
                                            FixedKernel kernel) const {
  constexpr std::size_t kTile = 512;  // 12 planes of 512 values: 24 KiB, in L1 with the labels
  static_assert(kTile <= kChunk, "a tile is classified as one chunk");
  std::uint32_t phase[3][kTile], amp[3][kTile];
  std::int32_t depth[3][kTile], combined[kTile], features[2][kTile];
  std::uint8_t flags[kTile];
  FixedPlanes p;
  for (std::size_t g = 0; g < 3; ++g) {
    p.phase[g] = phase[g];
    p.amp[g] = amp[g];
    p.depth[g] = depth[g];
  }
  p.flags = flags;
  p.combined = combined;
  p.features[0] = features[0];
  p.features[1] = features[1];
  const FixedThresholds th = fixed_thresholds(options);
  std::size_t classified = 0;
  for (std::size_t at = 0; at < tables.pixels; at += kTile) {
    const std::size_t m = std::min(kTile, tables.pixels - at);
    decode_pixels_fixed(raw, tables, at, m, th, p, kernel);
    classified += classify_chunk(combined, flags, nullptr, features[0], features[1], m, labels + at, kernel);
  }
  return classified;
}

}  // namespace tofmat
