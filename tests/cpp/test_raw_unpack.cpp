// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The 11-bit unpack's kernels (firmware/kinect/raw_unpack.hpp) against its
// definition (unpack_raw_reference: the layout of kinect2-protocol.md 2.3 read
// code by code, mapped through the device table of 2.4), bit for bit: the
// scalar kernel, the build's vector kernel (NEON on aarch64, run under
// qemu-aarch64 in the cross build; AVX2 on x86-64 CPUs that have it) and the
// dispatch, on random bytes, packed codes, extremes, row ranges and column
// ranges; that nothing outside the pixels asked for is written, and that a
// kernel reads only the stored rows of its rows (guard pages on both sides of
// a row).
#include <gtest/gtest.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/raw_lut.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/raw_unpack.hpp"

namespace {

using namespace tofmat::kinect;
using tofmat::FixedKernel;

// No code maps to it (values are within +-16320, or 32767): an element still
// holding it was not written.
constexpr std::int16_t kUnwritten = 0x5A5A;

using RegionFn = void (*)(const std::uint8_t*, std::int16_t*, const tofmat::PixelRegion&);
struct Kernel {
  std::string name;
  RegionFn region;
  void rows(const std::uint8_t* sub, std::int16_t* raw, int y0, int y1) const {
    region(sub, raw, tofmat::PixelRegion{0, y0, kWidth, y1});
  }
};

void best_region(const std::uint8_t* s, std::int16_t* r, const tofmat::PixelRegion& g) { unpack_raw_region(s, r, g); }
void scalar_region(const std::uint8_t* s, std::int16_t* r, const tofmat::PixelRegion& g) {
  unpack_raw_region(s, r, g, FixedKernel::kScalar);
}
// unpack_raw_rows for whole rows, unpack_raw_region otherwise.
void best_rows_or_region(const std::uint8_t* s, std::int16_t* r, const tofmat::PixelRegion& g) {
  if (g.x0 == 0 && g.x1 == kWidth) {
    unpack_raw_rows(s, r, g.y0, g.y1);
  } else {
    unpack_raw_region(s, r, g);
  }
}

// Every kernel this machine can run, and the ways through the dispatch.
std::vector<Kernel> kernels() {
  std::vector<Kernel> k{{"scalar kernel", unpack_region_scalar},
                        {"dispatch kScalar", scalar_region},
                        {"dispatch kBest", best_region},
                        {"dispatch kBest (rows)", best_rows_or_region}};
#if defined(__aarch64__)
  k.push_back({"neon kernel", unpack_region_neon});
#endif
#if defined(__x86_64__)
  if (tofmat::cpu_has_avx2()) k.push_back({"avx2 kernel", unpack_region_avx2});
#endif
  return k;
}

std::vector<std::uint8_t> random_bytes(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> b(n);
  for (auto& v : b) v = static_cast<std::uint8_t>(rng());
  return b;
}

std::vector<std::int16_t> reference(const std::uint8_t* sub, int y0 = 0, int y1 = kHeight) {
  std::vector<std::int16_t> r(kPixels, kUnwritten);
  unpack_raw_reference(sub, r.data(), y0, y1);
  return r;
}

// The pixels of [x0, x1) x [y0, y1) equal the definition's, every other
// element is untouched.
void expect_region(const std::vector<std::int16_t>& got, const std::vector<std::int16_t>& want,
                   const tofmat::PixelRegion& g, const std::string& what) {
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
      if (y >= g.y0 && y < g.y1 && x >= g.x0 && x < g.x1) {
        ASSERT_EQ(got[i], want[i]) << what << ": region x [" << g.x0 << ", " << g.x1 << ") y [" << g.y0 << ", " << g.y1
                                   << "), at x " << x << " y " << y;
      } else {
        ASSERT_EQ(got[i], kUnwritten) << what << ": region x [" << g.x0 << ", " << g.x1 << ") y [" << g.y0 << ", "
                                      << g.y1 << ") wrote x " << x << " y " << y;
      }
    }
  }
}

void expect_rows(const std::vector<std::int16_t>& got, const std::vector<std::int16_t>& want, int y0, int y1,
                 const std::string& what) {
  expect_region(got, want, tofmat::PixelRegion{0, y0, kWidth, y1}, what);
}

void expect_every_kernel_equals_the_definition(const std::uint8_t* sub, const std::string& what) {
  const auto want = reference(sub);
  for (const auto& k : kernels()) {
    std::vector<std::int16_t> got(kPixels, kUnwritten);
    k.rows(sub, got.data(), 0, kHeight);
    expect_rows(got, want, 0, kHeight, what + ", " + k.name);
  }
}

// Every kernel gives the device's value of each packed code (columns 0 and 511 read code 0).
void expect_every_kernel_gives_the_device_values(const std::uint8_t* sub, const std::vector<std::uint16_t>& codes,
                                                 const std::string& what) {
  for (const auto& k : kernels()) {
    std::vector<std::int16_t> got(kPixels, kUnwritten);
    k.rows(sub, got.data(), 0, kHeight);
    for (std::size_t i = 0; i < kPixels; ++i) {
      const int x = static_cast<int>(i % kWidth);
      const std::int16_t want = (x == 0 || x == kWidth - 1) ? std::int16_t{0} : tofmat::raw_code_value(codes[i]);
      ASSERT_EQ(got[i], want) << what << ", " << k.name << ": pixel " << i << " code " << codes[i];
    }
  }
}

std::vector<std::uint8_t> packed(const std::vector<std::uint16_t>& codes) {
  std::vector<std::uint8_t> sub(kSubImageBytes);
  pack_codes(codes.data(), sub.data());
  return sub;
}

TEST(RawUnpackKernels, BestKernelIsTheBuildsVectorKernel) {
#if defined(__aarch64__)
  EXPECT_STREQ(best_unpack_kernel(), "neon");
#elif defined(__x86_64__)
  EXPECT_STREQ(best_unpack_kernel(), tofmat::cpu_has_avx2() ? "avx2" : "scalar");
  if (!tofmat::cpu_has_avx2()) std::printf("note: this CPU has no AVX2: only the scalar kernel is tested here\n");
#else
  EXPECT_STREQ(best_unpack_kernel(), "scalar");
#endif
}

TEST(RawUnpackKernels, EqualTheDefinitionOnRandomBytes) {
  for (std::uint32_t seed : {1u, 2u, 3u, 4u}) {
    const auto sub = random_bytes(kSubImageBytes, seed);
    expect_every_kernel_equals_the_definition(sub.data(), "random bytes, seed " + std::to_string(seed));
  }
}

TEST(RawUnpackKernels, EqualTheDefinitionOnASubImageAtAnyAlignment) {
  const auto bytes = random_bytes(kSubImageBytes + 64, 5);
  for (std::size_t offset : {1u, 3u, 5u, 7u, 13u, 31u}) {
    // A copy that ends exactly where its allocation ends (sanitizer builds
    // see any read past it).
    const std::vector<std::uint8_t> sub(bytes.begin() + static_cast<std::ptrdiff_t>(offset),
                                        bytes.begin() + static_cast<std::ptrdiff_t>(offset + kSubImageBytes));
    std::vector<std::uint8_t> shifted(kSubImageBytes + offset);
    std::memcpy(shifted.data() + offset, sub.data(), kSubImageBytes);
    expect_every_kernel_equals_the_definition(shifted.data() + offset, "offset " + std::to_string(offset));
  }
}

TEST(RawUnpackKernels, EveryCodeAtEveryBitOffsetGoesThroughTheDeviceTable) {
  // Slot p of row y carries (513 y + p) mod 2048: every code at every slot
  // residue p mod 8 (the bit offset 11 p mod 8 within its byte) over 8 rows.
  std::vector<std::uint16_t> codes(kPixels);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const int slot = 128 * (x % 4) + x / 4;
      codes[static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x)] =
          static_cast<std::uint16_t>((513 * y + slot) % 2048);
    }
  }
  const auto sub = packed(codes);
  expect_every_kernel_gives_the_device_values(sub.data(), codes, "every code");
  expect_every_kernel_equals_the_definition(sub.data(), "every code");
}

TEST(RawUnpackKernels, PackThenUnpackGivesTheDeviceValuesExceptTheBorderColumns) {
  for (std::uint32_t seed : {11u, 12u}) {
    std::mt19937 rng(seed);
    std::vector<std::uint16_t> codes(kPixels);
    for (auto& c : codes) {
      const auto u = rng();
      // One in 16 saturated ("minus zero"), the rest any code.
      c = static_cast<std::uint16_t>(u % 16 == 0 ? tofmat::kRawSaturationCode : (u >> 4) & 0x7FF);
    }
    const auto sub = packed(codes);
    expect_every_kernel_gives_the_device_values(sub.data(), codes, "random codes");
  }
}

TEST(RawUnpackKernels, EqualTheDefinitionOnUniformAndExtremeSubImages) {
  for (int byte : {0x00, 0xFF, 0x80, 0x01, 0x55, 0xAA, 0x7F}) {
    const std::vector<std::uint8_t> sub(kSubImageBytes, static_cast<std::uint8_t>(byte));
    expect_every_kernel_equals_the_definition(sub.data(), "every byte " + std::to_string(byte));
  }
  // Every pixel saturated, the largest magnitudes of both signs, minus one
  // step, the smallest nonzero: each kernel's value arithmetic at its ends.
  for (int c : {1024, 1023, 2047, 1022, 2046, 1, 1025, 255, 256, 1279, 1280, 0}) {
    const auto code = static_cast<std::uint16_t>(c);
    const std::vector<std::uint16_t> codes(kPixels, code);
    const auto sub = packed(codes);
    expect_every_kernel_equals_the_definition(sub.data(), "every code " + std::to_string(code));
    std::vector<std::int16_t> got(kPixels, kUnwritten);
    unpack_raw_rows(sub.data(), got.data(), 0, kHeight);
    EXPECT_EQ(got[kWidth + 1], tofmat::raw_code_value(code));
    EXPECT_EQ(got[kWidth], 0);
    EXPECT_EQ(got[2 * kWidth - 1], 0);
  }
}

const std::vector<std::pair<int, int>> kRanges = {{0, 424},   {0, 1},   {423, 424}, {211, 212}, {212, 213}, {211, 213},
                                                  {210, 214}, {0, 212}, {212, 424}, {188, 236}, {1, 423},   {100, 101},
                                                  {300, 301}, {0, 0},   {212, 212}, {424, 424}};

TEST(RawUnpackKernels, RowRangesWriteTheirRowsAndNothingElse) {
  const auto sub = random_bytes(kSubImageBytes, 21);
  const auto want = reference(sub.data());
  for (const auto& [y0, y1] : kRanges) {
    // The definition itself keeps to its rows too.
    expect_rows(reference(sub.data(), y0, y1), want, y0, y1, "definition");
    for (const auto& k : kernels()) {
      std::vector<std::int16_t> got(kPixels, kUnwritten);
      k.rows(sub.data(), got.data(), y0, y1);
      expect_rows(got, want, y0, y1, k.name);
    }
  }
}

TEST(RawUnpackKernels, PacketRowsFillEverySubImagesRowsAndNothingElse) {
  // A packet of exactly nine sub-images (the tenth is optional).
  const auto packet = random_bytes(kUsedSubImages * kSubImageBytes, 31);
  std::vector<std::vector<std::int16_t>> want;
  want.reserve(kUsedSubImages);
  for (int s = 0; s < kUsedSubImages; ++s) want.push_back(reference(packet.data() + s * kSubImageBytes));
  for (FixedKernel kernel : {FixedKernel::kScalar, FixedKernel::kBest}) {
    for (const auto& [y0, y1] : kRanges) {
      std::vector<std::int16_t> got(kUsedSubImages * kPixels, kUnwritten);
      unpack_depth_packet_rows(packet.data(), got.data(), y0, y1, kernel);
      for (int s = 0; s < kUsedSubImages; ++s) {
        const std::vector<std::int16_t> one(got.begin() + static_cast<std::ptrdiff_t>(s * kPixels),
                                            got.begin() + static_cast<std::ptrdiff_t>((s + 1) * kPixels));
        expect_rows(one, want[static_cast<std::size_t>(s)], y0, y1,
                    "packet sub-image " + std::to_string(s) + (kernel == FixedKernel::kBest ? " best" : " scalar"));
      }
    }
    std::vector<std::int16_t> full(kUsedSubImages * kPixels, kUnwritten), rows(full);
    unpack_depth_packet(packet.data(), full.data(), kernel);
    unpack_depth_packet_rows(packet.data(), rows.data(), 0, kHeight, kernel);
    EXPECT_EQ(full, rows);
  }
  // unpack_raw is the whole sub-image.
  std::vector<std::int16_t> one(kPixels, kUnwritten);
  unpack_raw(packet.data(), one.data());
  EXPECT_EQ(one, want[0]);
}

TEST(RawUnpackKernels, ColumnRangesWriteTheirPixelsAndNothingElse) {
  const auto sub = random_bytes(kSubImageBytes, 22);
  const auto want = reference(sub.data());
  // Block edges (32 columns: NEON and scalar; 64: AVX2) and their
  // neighbours, the border columns, a 48-column region at the centre.
  const std::vector<int> xs = {0,   1,   2,   3,   4,   5,   31,  32,  33,  63,  64,  65,  96,  127, 128, 232, 255,
                               256, 257, 280, 383, 384, 447, 448, 449, 479, 480, 481, 500, 508, 509, 510, 511, 512};
  const auto all = kernels();
  std::vector<std::int16_t> got(kPixels, kUnwritten);
  for (const auto& [y0, y1] : std::vector<std::pair<int, int>>{{211, 213}, {423, 424}, {0, 1}, {100, 101}}) {
    for (std::size_t i = 0; i < xs.size(); ++i) {
      for (std::size_t j = i; j < xs.size(); ++j) {
        const tofmat::PixelRegion g{xs[i], y0, xs[j], y1};
        for (const auto& k : all) {
          k.region(sub.data(), got.data(), g);
          // The region's rows and their neighbours (the kernels write through
          // a row's own pointer only; the rectangle below checks the whole
          // frame), then back to kUnwritten.
          for (int y = std::max(y0 - 1, 0); y <= std::min(y1, kHeight - 1); ++y) {
            for (int x = 0; x < kWidth; ++x) {
              const std::size_t p = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
              const bool inside = y >= y0 && y < y1 && x >= g.x0 && x < g.x1;
              if (got[p] != (inside ? want[p] : kUnwritten)) {
                FAIL() << k.name << ": x [" << g.x0 << ", " << g.x1 << ") y [" << y0 << ", " << y1 << ") at x " << x
                       << " y " << y << ": " << got[p] << ", not " << (inside ? want[p] : kUnwritten);
              }
              got[p] = kUnwritten;
            }
          }
        }
      }
    }
  }
  // A rectangle over both halves (stored rows 188..211 and 400..423), each kernel, the whole frame checked.
  for (const auto& k : all) {
    const tofmat::PixelRegion g{232, 188, 280, 236};
    std::vector<std::int16_t> one(kPixels, kUnwritten);
    k.region(sub.data(), one.data(), g);
    expect_region(one, want, g, k.name);
  }
}

TEST(RawUnpackKernels, PacketRegionFillsEverySubImagesRectangleAndNothingElse) {
  const auto packet = random_bytes(kUsedSubImages * kSubImageBytes, 32);
  for (FixedKernel kernel : {FixedKernel::kScalar, FixedKernel::kBest}) {
    for (const tofmat::PixelRegion& g : {tofmat::PixelRegion{232, 188, 280, 236}, tofmat::PixelRegion{0, 0, 512, 424},
                                         tofmat::PixelRegion{500, 420, 512, 424}, tofmat::PixelRegion{7, 3, 7, 9}}) {
      std::vector<std::int16_t> got(kUsedSubImages * kPixels, kUnwritten);
      unpack_depth_packet_region(packet.data(), got.data(), g, kernel);
      for (int s = 0; s < kUsedSubImages; ++s) {
        const std::vector<std::int16_t> one(got.begin() + static_cast<std::ptrdiff_t>(s * kPixels),
                                            got.begin() + static_cast<std::ptrdiff_t>((s + 1) * kPixels));
        expect_region(one, reference(packet.data() + s * kSubImageBytes), g, "packet sub-image " + std::to_string(s));
      }
    }
  }
}

TEST(RawUnpackKernels, RowsOutsideTheFrameAreRefused) {
  const auto sub = random_bytes(kSubImageBytes, 41);
  std::vector<std::int16_t> raw(kUsedSubImages * kPixels, kUnwritten);
  for (const auto& [y0, y1] : std::vector<std::pair<int, int>>{{-1, 10}, {0, 425}, {10, 9}, {424, 425}, {-5, -1}}) {
    EXPECT_THROW(unpack_raw_rows(sub.data(), raw.data(), y0, y1), std::invalid_argument) << y0 << " " << y1;
    EXPECT_THROW(unpack_raw_reference(sub.data(), raw.data(), y0, y1), std::invalid_argument) << y0 << " " << y1;
  }
  for (const tofmat::PixelRegion& g :
       {tofmat::PixelRegion{-1, 0, 10, 10}, tofmat::PixelRegion{0, 0, 513, 10}, tofmat::PixelRegion{20, 0, 19, 10},
        tofmat::PixelRegion{0, 5, 10, 4}, tofmat::PixelRegion{0, 0, 10, 425}}) {
    EXPECT_THROW(unpack_raw_region(sub.data(), raw.data(), g), std::invalid_argument) << g.x0 << " " << g.x1;
  }
  std::vector<std::uint8_t> packet(kUsedSubImages * kSubImageBytes);
  EXPECT_THROW(unpack_depth_packet_rows(packet.data(), raw.data(), 5, 4), std::invalid_argument);
  EXPECT_THROW(unpack_depth_packet_region(packet.data(), raw.data(), tofmat::PixelRegion{0, 0, 600, 1}),
               std::invalid_argument);
  for (auto v : raw) ASSERT_EQ(v, kUnwritten);
}

// One stored row placed against an inaccessible page, after it or before it:
// a kernel that reads a byte outside the row faults.
class GuardedRow {
 public:
  GuardedRow() : page_(static_cast<std::size_t>(sysconf(_SC_PAGESIZE))) {
    void* p = mmap(nullptr, 3 * page_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::runtime_error("mmap failed");
    base_ = static_cast<std::uint8_t*>(p);
    if (mprotect(base_, page_, PROT_NONE) != 0 || mprotect(base_ + 2 * page_, page_, PROT_NONE) != 0) {
      throw std::runtime_error("mprotect failed");
    }
  }
  ~GuardedRow() { munmap(base_, 3 * page_); }
  GuardedRow(const GuardedRow&) = delete;
  GuardedRow& operator=(const GuardedRow&) = delete;

  // The row's first byte: just after the low guard, or kRowBytes before the high one.
  std::uint8_t* row(bool against_end) { return against_end ? base_ + 2 * page_ - kRowBytes : base_ + page_; }

 private:
  std::size_t page_;
  std::uint8_t* base_ = nullptr;
};

TEST(RawUnpackKernels, ReadOnlyTheStoredRowOfTheirRow) {
  const auto sub = random_bytes(kSubImageBytes, 51);
  const auto want = reference(sub.data());
  GuardedRow guard;
  auto all = kernels();
  all.push_back({"definition", [](const std::uint8_t* s, std::int16_t* r, const tofmat::PixelRegion& g) {
                   unpack_raw_reference(s, r, g.y0, g.y1);
                 }});
  for (int y : {0, 1, 100, 211, 212, 213, 300, 422, 423}) {
    const std::size_t stored = static_cast<std::size_t>(stored_row_of_output_row(y));
    for (bool against_end : {false, true}) {
      std::uint8_t* row = guard.row(against_end);
      std::memcpy(row, sub.data() + stored * kRowBytes, kRowBytes);
      // The sub-image's start as the kernels compute it back from the row
      // (only the row itself is ever dereferenced). It lies before the
      // buffer, where pointer arithmetic would be undefined: hence integers.
      const std::uintptr_t start_address = reinterpret_cast<std::uintptr_t>(row) - stored * kRowBytes;
      // NOLINTNEXTLINE(performance-no-int-to-ptr): the integer detour above is the point; nothing to optimise.
      const auto* start = reinterpret_cast<const std::uint8_t*>(start_address);
      for (const auto& k : all) {
        std::vector<std::int16_t> got(kPixels, kUnwritten);
        k.rows(start, got.data(), y, y + 1);
        expect_rows(got, want, y, y + 1, k.name + (against_end ? " (guard after)" : " (guard before)"));
      }
      // The first and the last block alone, through the column-range path.
      for (const auto& k : kernels()) {
        for (const tofmat::PixelRegion& g :
             {tofmat::PixelRegion{0, y, 5, y + 1}, tofmat::PixelRegion{500, y, 512, y + 1}}) {
          std::vector<std::int16_t> got(kPixels, kUnwritten);
          k.region(start, got.data(), g);
          expect_region(got, want, g, k.name + (against_end ? " (guard after)" : " (guard before)"));
        }
      }
    }
  }
}

}  // namespace
