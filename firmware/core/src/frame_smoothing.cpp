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

// |feature| < 2^14 mm: Q8 within +-2^22, so 225 of them sum within int32.
constexpr std::int32_t kQ8Bound = 1 << 22;

std::int32_t q8_of(std::int32_t v16) {
  const std::int32_t v = static_cast<std::int32_t>((static_cast<std::int64_t>(v16) + 128) >> 8);
  return std::clamp(v, -kQ8Bound, kQ8Bound);
}

// The mean's division, floor(N / n) with N = 256 S + floor(n / 2) and n in
// [1, 225], as floor((N + 1/2) (1 / n)) in IEEE-754 binary64 (vectorisable,
// no integer divide; the same on every target: each operation is correctly
// rounded and none can be fused into another). Exact: (N + 1/2) / n lies at
// least 1 / (2 n) >= 1/450 from every integer, and |N| < 2^38 keeps the two
// roundings' error below 2^-13 (FrameSmoothing tests compare it with the
// integer definition). Biased by 2^30 per pixel of the window (above any
// |256 S| / n), the numerator is positive and below 2^39.
constexpr std::int64_t kMeanBiasInt = std::int64_t{1} << 30;
constexpr double kMeanBias = 1073741824.0;  // 2^30
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
#else
  v = max16(v, __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15, 0, 1, 2, 3, 4, 5, 6, 7));
  v = max16(v, __builtin_shufflevector(v, v, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3));
  v = max16(v, __builtin_shufflevector(v, v, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1));
  v = max16(v, __builtin_shufflevector(v, v, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0));
  return v[0];
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

void BoxMeanFilter::add_row(const std::int32_t* f0, const std::int32_t* f1, const std::uint8_t* flags, int y,
                            int sign) {
  const std::size_t at = static_cast<std::size_t>(y) * static_cast<std::size_t>(width_);
  for (std::size_t x = 0; x < static_cast<std::size_t>(width_); ++x) {
    const std::int32_t ok = flags[at + x] == 0 ? sign : 0;
    col0_[x] += ok * q8_of(f0[at + x]);
    col1_[x] += ok * q8_of(f1[at + x]);
    coln_[x] += ok;
  }
}

void BoxMeanFilter::apply(const std::int32_t* f0, const std::int32_t* f1, const std::uint8_t* flags, int y0, int y1,
                          std::int32_t* out0, std::int32_t* out1) {
  check_band(height_, y0, y1);
  const int r = radius_, w = width_;
  const auto uw = static_cast<std::size_t>(w), span = static_cast<std::size_t>(2 * r + 1);
  std::fill(col0_.begin(), col0_.end(), 0);
  std::fill(col1_.begin(), col1_.end(), 0);
  std::fill(coln_.begin(), coln_.end(), 0);
  for (int y = std::max(0, y0 - r); y < std::min(height_, y0 + r + 1); ++y) add_row(f0, f1, flags, y, 1);
  for (int y = y0; y < y1; ++y) {
    // The columns hold rows [y - r, y + r] of the frame. Their prefix sums,
    // padded with r copies of the first and the last (the window clipped at
    // the edges): pixel x's window sum is P[x + 2r + 1] - P[x], no branch.
    // (Modulo 2^32: a whole row's sum may not fit int32, a window's does.)
    std::uint32_t a0 = 0, a1 = 0, an = 0;
    std::size_t k = 0;
    for (; k <= static_cast<std::size_t>(r); ++k) pre0_[k] = pre1_[k] = pren_[k] = 0;
    for (std::size_t x = 0; x < uw; ++x, ++k) {
      pre0_[k] = a0 += static_cast<std::uint32_t>(col0_[x]);
      pre1_[k] = a1 += static_cast<std::uint32_t>(col1_[x]);
      pren_[k] = an += static_cast<std::uint32_t>(coln_[x]);
    }
    for (; k < pre0_.size(); ++k) pre0_[k] = a0, pre1_[k] = a1, pren_[k] = an;
    const std::size_t at = static_cast<std::size_t>(y) * uw;
    for (std::size_t x = 0; x < uw; ++x) {
      const auto s0 = static_cast<std::int32_t>(pre0_[x + span] - pre0_[x]);
      const auto s1 = static_cast<std::int32_t>(pre1_[x + span] - pre1_[x]);
      const std::int32_t n = std::max(static_cast<std::int32_t>(pren_[x + span] - pren_[x]), 1);  // (0: flagged)
      // (Biased by n 2^30 to a positive numerator: truncation is then floor,
      // one conversion instruction; the quotient's bias 2^30 comes off after.)
      const double inv = 1.0 / static_cast<double>(n);
      const double half_n = static_cast<double>(n >> 1) + 0.5 + static_cast<double>(n) * kMeanBias;
      const auto m0 = static_cast<std::int64_t>((256.0 * static_cast<double>(s0) + half_n) * inv);
      const auto m1 = static_cast<std::int64_t>((256.0 * static_cast<double>(s1) + half_n) * inv);
      const bool ok = flags[at + x] == 0;
      out0[at + x] = ok ? static_cast<std::int32_t>(m0 - kMeanBiasInt) : kFixedInvalid;
      out1[at + x] = ok ? static_cast<std::int32_t>(m1 - kMeanBiasInt) : kFixedInvalid;
    }
    if (y + r + 1 < height_) add_row(f0, f1, flags, y + r + 1, 1);
    if (y - r >= 0) add_row(f0, f1, flags, y - r, -1);
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
}

void MajorityFilter::add_row(const std::uint8_t* labels, int y, int sign) {
  const std::uint8_t* row = labels + static_cast<std::size_t>(y) * static_cast<std::size_t>(width_);
  const auto delta = static_cast<std::uint8_t>(sign);  // +1 or 255 (-1, wrapping)
  const auto dump = static_cast<std::uint8_t>(classes_);
  const std::size_t lanes = lanes_, w = static_cast<std::size_t>(width_);  // (locals: see apply_chunks)
  std::uint8_t* columns = columns_.data();
  for (std::size_t x = 0; x < w; ++x) {
    const std::uint8_t slot = row[x] < dump ? row[x] : dump;
    columns[x * lanes + slot] = static_cast<std::uint8_t>(columns[x * lanes + slot] + delta);
  }
}

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
  for (int y = std::max(0, y0 - r); y < std::min(h, y0 + r + 1); ++y) add_row(labels, y, 1);
  const std::uint8_t* columns = columns_.data();
  auto column = [&](int x, std::size_t j) { return load16(columns + static_cast<std::size_t>(x) * lanes + 16 * j); };
  V16 keep[C], window[C];
  for (std::size_t j = 0; j < chunks; ++j) keep[j] = load16(&keep_[16 * j]);
  const auto dump_chunk = static_cast<std::size_t>(classes) / 16, dump_lane = static_cast<std::size_t>(classes) % 16;
  for (int y = y0; y < y1; ++y) {
    const std::size_t at = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    const int rows = std::min(y + r, h - 1) - std::max(y - r, 0) + 1;  // the window's, clipped
    for (std::size_t j = 0; j < chunks; ++j) window[j] = V16{};
    for (int x = 0; x < std::min(r, w); ++x)
      for (std::size_t j = 0; j < chunks; ++j) window[j] += column(x, j);
    for (int x = 0; x < w; ++x) {
      if (x + r < w)
        for (std::size_t j = 0; j < chunks; ++j) window[j] += column(x + r, j);
      if (x - r - 1 >= 0)
        for (std::size_t j = 0; j < chunks; ++j) window[j] -= column(x - r - 1, j);
      const std::uint8_t own = labels[at + static_cast<std::size_t>(x)];
      const int cols = std::min(x + r, w - 1) - std::max(x - r, 0) + 1;
      const int labelled = rows * cols - window[dump_chunk][dump_lane];  // pixels with a label in the window
      std::uint8_t label = own;
      if (own < classes) {
        // Most pixels lie inside a region, where their own label is more than
        // half the votes: then it is the one most frequent, without a search.
        if (2 * window[own / 16][own % 16] > labelled) {
          out[at + static_cast<std::size_t>(x)] = own;
          continue;
        }
      } else if (2 * labelled <= rows * cols) {  // no label, and labels are not the majority
        out[at + static_cast<std::size_t>(x)] = own;
        continue;
      }
      V16 best = window[0] & keep[0];
      for (std::size_t j = 1; j < chunks; ++j) best = max16(best, window[j] & keep[j]);
      const std::uint8_t m = horizontal_max(best);
      if (own >= classes || window[own / 16][own % 16] != m) {
        for (std::size_t j = 0;; ++j) {  // the lowest class with m votes (there is one)
          const V16 v = window[j] & keep[j];
          if (horizontal_max(v) == m) {
            label = static_cast<std::uint8_t>(16 * j + static_cast<std::size_t>(first_equal(v, m)));
            break;
          }
        }
      }
      out[at + static_cast<std::size_t>(x)] = label;
    }
    if (y + r + 1 < h) add_row(labels, y + r + 1, 1);
    if (y - r >= 0) add_row(labels, y - r, -1);
  }
}

}  // namespace tofmat
