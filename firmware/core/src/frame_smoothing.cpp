// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Box mean of the features and majority filter of the label map
// (frame_smoothing.hpp). Both keep, per column, the sum over the window's
// rows and slide it down one row at a time (one row in, one row out), and
// slide a window sum along each row from those columns: a few operations per
// pixel whatever the window's side.
#include "tofmat/core/frame_smoothing.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "frame_smoothing_kernels.hpp"
#include "tofmat/core/fixed_decode.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tofmat {
namespace {

void check_frame(int width, int height, int side) {
  if (width < 1 || height < 1) throw std::invalid_argument("frame size must be positive");
  if (side < 1 || side > 15 || side % 2 == 0)
    throw std::invalid_argument("smoothing side must be odd and in [1, 15], got " + std::to_string(side));
}

void check_band(int height, int y0, int y1) {
  if (y0 < 0 || y1 > height || y0 > y1)
    throw std::invalid_argument("band [" + std::to_string(y0) + ", " + std::to_string(y1) + ") is outside the frame");
}

// 16 counts side by side (GCC/Clang vector extension: one instruction per
// operation on NEON and SSE2). Counts stay in [0, 225]; additions and
// subtractions wrap only transiently.
typedef std::uint8_t V16 __attribute__((vector_size(16)));

V16 load16(const std::uint8_t* p) {
  V16 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

V16 max16(V16 a, V16 b) { return a > b ? a : b; }

std::uint8_t horizontal_max(V16 v) {
#if defined(__aarch64__)
  uint8x16_t a;
  std::memcpy(&a, &v, sizeof a);
  return vmaxvq_u8(a);
#elif defined(__SSE2__)
  __m128i a;
  std::memcpy(&a, &v, sizeof a);
  a = _mm_max_epu8(a, _mm_srli_si128(a, 8));
  a = _mm_max_epu8(a, _mm_srli_si128(a, 4));
  a = _mm_max_epu8(a, _mm_srli_si128(a, 2));
  a = _mm_max_epu8(a, _mm_srli_si128(a, 1));
  return static_cast<std::uint8_t>(_mm_cvtsi128_si32(a));
#else  // (other targets: lane by lane)
  std::uint8_t m = 0;
  for (int i = 0; i < 16; ++i) m = v[i] > m ? v[i] : m;
  return m;
#endif
}

// The first lane of v equal to m (there is one), 0..15.
int first_equal(V16 v, std::uint8_t m) {
  const V16 eq = v == m;  // 0xFF where equal
#if defined(__SSE2__)
  __m128i e;
  std::memcpy(&e, &eq, sizeof e);
  return __builtin_ctz(static_cast<unsigned>(_mm_movemask_epi8(e)));
#else
  std::uint64_t half[2];
  std::memcpy(half, &eq, sizeof half);
  return half[0] ? __builtin_ctzll(half[0]) / 8 : 8 + __builtin_ctzll(half[1]) / 8;
#endif
}

}  // namespace

namespace smoothing_detail {

namespace {
std::int32_t q8_of(std::int32_t v16) { return static_cast<std::int32_t>((static_cast<std::int64_t>(v16) + 128) >> 8); }
}  // namespace

void box_slide_scalar(const BoxRows& rows, std::size_t w, const BoxColumns& c) {
  for (std::size_t x = 0; x < w; ++x) {
    std::int32_t d0 = 0, d1 = 0, dn = 0;
    if (rows.in0 != nullptr && rows.in_flags[x] == 0) d0 += q8_of(rows.in0[x]), d1 += q8_of(rows.in1[x]), ++dn;
    if (rows.out0 != nullptr && rows.out_flags[x] == 0) d0 -= q8_of(rows.out0[x]), d1 -= q8_of(rows.out1[x]), --dn;
    c.col0[x] += d0;
    c.col1[x] += d1;
    c.coln[x] += dn;
  }
}

void box_prefix_scalar(std::size_t w, std::size_t r, const BoxColumns& c) {
  // (Modulo 2^32: a whole row's sum may not fit int32, a window's does.)
  std::uint32_t a0 = 0, a1 = 0, an = 0;
  std::size_t k = 0;
  for (; k <= r; ++k) c.pre0[k] = c.pre1[k] = c.pren[k] = 0;
  for (std::size_t x = 0; x < w; ++x, ++k) {
    c.pre0[k] = a0 += static_cast<std::uint32_t>(c.col0[x]);
    c.pre1[k] = a1 += static_cast<std::uint32_t>(c.col1[x]);
    c.pren[k] = an += static_cast<std::uint32_t>(c.coln[x]);
  }
  for (; k < w + 2 * r + 1; ++k) c.pre0[k] = a0, c.pre1[k] = a1, c.pren[k] = an;
}

void box_means_scalar(std::size_t w, std::size_t r, const BoxColumns& c, const std::uint8_t* flags, std::int32_t* out0,
                      std::int32_t* out1) {
  const std::size_t span = 2 * r + 1;
  const auto mean = [](std::int32_t s, double half_n, double inv) {
    const auto q = static_cast<std::int64_t>((256.0 * static_cast<double>(s) + half_n) * inv) - kMeanBias;
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(q, INT32_MIN + 1, INT32_MAX));
  };
  for (std::size_t x = 0; x < w; ++x) {
    const auto s0 = static_cast<std::int32_t>(c.pre0[x + span] - c.pre0[x]);
    const auto s1 = static_cast<std::int32_t>(c.pre1[x + span] - c.pre1[x]);
    const std::int32_t n = std::max(static_cast<std::int32_t>(c.pren[x + span] - c.pren[x]), 1);  // (0: flagged)
    const double nd = static_cast<double>(n);
    const double inv = 1.0 / nd;
    const double half_n = (static_cast<double>(n >> 1) + 0.5) + nd * kMeanBiasF;
    const bool ok = flags[x] == 0;
    out0[x] = ok ? mean(s0, half_n, inv) : kFixedInvalid;
    out1[x] = ok ? mean(s1, half_n, inv) : kFixedInvalid;
  }
}

}  // namespace smoothing_detail

BoxMeanFilter::BoxMeanFilter(int width, int height, int side) : width_(width), height_(height), radius_(side / 2) {
  check_frame(width, height, side);
  const auto w = static_cast<std::size_t>(width);
  col0_.assign(w, 0);
  col1_.assign(w, 0);
  coln_.assign(w, 0);
  const std::size_t padded = w + 2 * static_cast<std::size_t>(radius_) + 1;
  pre0_.assign(padded, 0);
  pre1_.assign(padded, 0);
  pren_.assign(padded, 0);
}

void BoxMeanFilter::apply(const std::int32_t* f0, const std::int32_t* f1, const std::uint8_t* flags, int y0, int y1,
                          std::int32_t* out0, std::int32_t* out1, FixedKernel kernel) {
  using namespace smoothing_detail;
  check_band(height_, y0, y1);
  const int r = radius_, h = height_;
  const auto uw = static_cast<std::size_t>(width_), ur = static_cast<std::size_t>(r);
#if defined(__aarch64__)
  const bool neon = kernel == FixedKernel::kBest;
  const auto slide = neon ? box_slide_neon : box_slide_scalar;
  const auto prefix = neon ? box_prefix_neon : box_prefix_scalar;
  const auto means = neon ? box_means_neon : box_means_scalar;
#else
  (void)kernel;
  const auto slide = box_slide_scalar;
  const auto prefix = box_prefix_scalar;
  const auto means = box_means_scalar;
#endif
  const BoxColumns c{col0_.data(), col1_.data(), coln_.data(), pre0_.data(), pre1_.data(), pren_.data()};
  const auto row = [&](int y) { return static_cast<std::size_t>(y) * uw; };
  std::fill(col0_.begin(), col0_.end(), 0);
  std::fill(col1_.begin(), col1_.end(), 0);
  std::fill(coln_.begin(), coln_.end(), 0);
  for (int y = std::max(0, y0 - r); y < std::min(h, y0 + r + 1); ++y) {
    BoxRows in;
    in.in0 = f0 + row(y), in.in1 = f1 + row(y), in.in_flags = flags + row(y);
    slide(in, uw, c);
  }
  for (int y = y0; y < y1; ++y) {
    // The columns hold rows [y - r, y + r] of the frame: their prefix sums
    // along the row give each pixel's window sum without a branch.
    prefix(uw, ur, c);
    means(uw, ur, c, flags + row(y), out0 + row(y), out1 + row(y));
    BoxRows next;  // row y + r + 1 in, row y - r out
    if (y + r + 1 < h)
      next.in0 = f0 + row(y + r + 1), next.in1 = f1 + row(y + r + 1), next.in_flags = flags + row(y + r + 1);
    if (y - r >= 0) next.out0 = f0 + row(y - r), next.out1 = f1 + row(y - r), next.out_flags = flags + row(y - r);
    if (next.in0 != nullptr || next.out0 != nullptr) slide(next, uw, c);
  }
}

MajorityFilter::MajorityFilter(int width, int height, int side, int classes)
    : width_(width), height_(height), radius_(side / 2), classes_(classes) {
  check_frame(width, height, side);
  if (classes < 1 || classes > 255)
    throw std::invalid_argument("majority filter: classes must lie in [1, 255], got " + std::to_string(classes));
  lanes_ = (static_cast<std::size_t>(classes) + 1 + 15) / 16 * 16;
  columns_.assign(static_cast<std::size_t>(width) * lanes_, 0);
  keep_.assign(lanes_, 0);
  std::fill(keep_.begin(), keep_.begin() + classes, std::uint8_t{0xFF});
  const int r = radius_;
  for (int x = 0; x < width; ++x) cols_.push_back(std::min(x + r, width - 1) - std::max(x - r, 0) + 1);
}

// One row entering the columns' counts and one leaving (-1: none): per
// column, +1 for the entering pixel's slot, -1 for the leaving one's; a
// column whose two pixels have the same slot does not change (most of them,
// inside regions).
void MajorityFilter::slide(const std::uint8_t* labels, int y_in, int y_out) {
  const std::size_t lanes = lanes_, w = static_cast<std::size_t>(width_);  // (locals: see apply_chunks)
  const auto dump = static_cast<std::uint8_t>(lanes - 1);
  const auto classes = static_cast<std::uint8_t>(classes_);
  const auto slot = [&](std::uint8_t v) { return v < classes ? v : dump; };
  std::uint8_t* columns = columns_.data();
  const std::uint8_t* in = y_in < 0 ? nullptr : labels + static_cast<std::size_t>(y_in) * w;
  const std::uint8_t* out = y_out < 0 ? nullptr : labels + static_cast<std::size_t>(y_out) * w;
  if (in == nullptr && out == nullptr) return;
  if (in == nullptr || out == nullptr) {  // the band's first rows, or the frame's edges: one row alone
    const std::uint8_t* row = in != nullptr ? in : out;
    const std::uint8_t delta = in != nullptr ? 1 : 255;  // (-1, wrapping)
    for (std::size_t x = 0; x < w; ++x) columns[x * lanes + slot(row[x])] += delta;
    return;
  }
  for (std::size_t x0 = 0; x0 < w; x0 += 16) {
    const std::size_t x1 = std::min(x0 + 16, w);
    // Sixteen columns whose entering and leaving labels are all the same
    // change nothing: skipped at once.
    if (x1 == x0 + 16 && std::memcmp(in + x0, out + x0, 16) == 0) continue;
    for (std::size_t x = x0; x < x1; ++x) {
      const std::uint8_t si = slot(in[x]), so = slot(out[x]);
      if (si == so) continue;
      std::uint8_t* column = columns + x * lanes;
      ++column[si];
      --column[so];
    }
  }
}

namespace {

// The count of class k in a window held as C vectors of 16 counts (k < 16 C).
template <std::size_t C>
std::uint8_t count_of(const V16 (&window)[C], std::uint8_t k) {
#if defined(__aarch64__)
  if constexpr (C <= 4) {
    uint8x16_t t[4];
    for (std::size_t j = 0; j < C; ++j) std::memcpy(&t[j], &window[j], sizeof t[j]);
    const uint8x16_t idx = vdupq_n_u8(k);
    if constexpr (C == 1) return vgetq_lane_u8(vqtbl1q_u8(t[0], idx), 0);
    if constexpr (C == 2) return vgetq_lane_u8(vqtbl2q_u8(uint8x16x2_t{{t[0], t[1]}}, idx), 0);
    if constexpr (C == 3) return vgetq_lane_u8(vqtbl3q_u8(uint8x16x3_t{{t[0], t[1], t[2]}}, idx), 0);
    if constexpr (C == 4) return vgetq_lane_u8(vqtbl4q_u8(uint8x16x4_t{{t[0], t[1], t[2], t[3]}}, idx), 0);
  }
#endif
  return window[k / 16][k % 16];
}

}  // namespace

void MajorityFilter::apply(const std::uint8_t* labels, int y0, int y1, std::uint8_t* out) {
  check_band(height_, y0, y1);
  switch (lanes_ / 16) {  // up to 63 classes: the window's counts in registers
    case 1: return apply_chunks<1>(labels, y0, y1, out);
    case 2: return apply_chunks<2>(labels, y0, y1, out);
    case 3: return apply_chunks<3>(labels, y0, y1, out);
    case 4: return apply_chunks<4>(labels, y0, y1, out);
    default: return apply_chunks<16>(labels, y0, y1, out);
  }
}

// C: chunks of 16 lanes held (16: up to 16, lanes_ / 16 of them used).
template <std::size_t C>
void MajorityFilter::apply_chunks(const std::uint8_t* labels, int y0, int y1, std::uint8_t* out) {
  // (Members copied to locals: the uint8 stores to `out` may alias anything,
  // and the compiler would reload every member after each.)
  const int r = radius_, w = width_, h = height_, classes = classes_;
  const std::size_t lanes = lanes_, chunks = C == 16 ? lanes / 16 : C;
  std::fill(columns_.begin(), columns_.end(), std::uint8_t{0});
  for (int y = std::max(0, y0 - r); y < std::min(h, y0 + r + 1); ++y) slide(labels, y, -1);
  const std::uint8_t* columns = columns_.data();
  const int* cols = cols_.data();
  auto column = [&](int x, std::size_t j) { return load16(columns + static_cast<std::size_t>(x) * lanes + 16 * j); };
  V16 keep[C], window[C];
  for (std::size_t j = 0; j < C; ++j) keep[j] = window[j] = V16{};
  for (std::size_t j = 0; j < chunks; ++j) keep[j] = load16(&keep_[16 * j]);
  // The label of a window: `own` (a label or not) as the definition says.
  const auto decide = [&](std::uint8_t own, int area, std::uint8_t hint) -> std::uint8_t {
    const int labelled = area - (C == 16 ? window[chunks - 1][15] : window[C - 1][15]);  // (last lane: no label)
    if (own < classes) {
      // Inside a region the pixel's own label has more than half the votes:
      // then it is the one most frequent, without a search.
      if (2 * count_of<C>(window, own) > labelled) return own;
    } else if (2 * labelled <= area) {  // no label, and labels are not the window's majority
      return own;
    }
    // A label with more than half the votes is the only most frequent one
    // (ties cannot reach it): the previous pixel's result usually is.
    if (hint < classes && 2 * count_of<C>(window, hint) > labelled) return hint;
    V16 best = window[0] & keep[0];
    for (std::size_t j = 1; j < chunks; ++j) best = max16(best, window[j] & keep[j]);
    const std::uint8_t m = horizontal_max(best);
    if (own < classes && count_of<C>(window, own) == m) return own;
    for (std::size_t j = 0;; ++j) {  // the lowest class with m votes (there is one)
      const V16 v = window[j] & keep[j];
      if (horizontal_max(v) == m)
        return static_cast<std::uint8_t>(16 * j + static_cast<std::size_t>(first_equal(v, m)));
    }
  };
  for (int y = y0; y < y1; ++y) {
    const std::size_t at = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    const std::uint8_t* in = labels + at;
    std::uint8_t* o = out + at;
    const int rows = std::min(y + r, h - 1) - std::max(y - r, 0) + 1;  // the window's, clipped
    for (std::size_t j = 0; j < chunks; ++j) window[j] = V16{};
    for (int x = 0; x < std::min(r, w); ++x)
      for (std::size_t j = 0; j < chunks; ++j) window[j] += column(x, j);
    std::uint8_t hint = 255;
    // The left edge, the interior (every column in the window: no test), the right edge.
    const int left = std::min(r + 1, w), right = std::max(left, w - r);
    int x = 0;
    for (; x < left; ++x) {
      if (x + r < w)
        for (std::size_t j = 0; j < chunks; ++j) window[j] += column(x + r, j);
      o[x] = hint = decide(in[x], rows * cols[x], hint);
    }
    const int area = rows * (2 * r + 1);
    for (; x < right; ++x) {
      for (std::size_t j = 0; j < chunks; ++j) window[j] += column(x + r, j) - column(x - r - 1, j);
      o[x] = hint = decide(in[x], area, hint);
    }
    for (; x < w; ++x) {
      if (x - r - 1 >= 0)
        for (std::size_t j = 0; j < chunks; ++j) window[j] -= column(x - r - 1, j);
      o[x] = hint = decide(in[x], rows * cols[x], hint);
    }
    slide(labels, y + r + 1 < h ? y + r + 1 : -1, y - r >= 0 ? y - r : -1);
  }
}

}  // namespace tofmat
