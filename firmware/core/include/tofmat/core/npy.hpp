// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Reader for NumPy .npy arrays of floating-point values: the format of the
// real Kinect v2 database (Python 2 headers with `L` suffixes included).
//
// Accepted: format versions 1.0, 2.0 and 3.0; descr '<f8' or '<f4' (explicit
// little-endian only, so the meaning never depends on the host); C order; 1 to 4
// dimensions; at most kNpyMaxElements elements; data exactly filling the rest
// of the file. Anything else is a FormatError that names the problem.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace tofmat {

inline constexpr std::size_t kNpyMaxHeaderBytes = 64 * 1024;
inline constexpr std::size_t kNpyMaxElements = std::size_t{1} << 24;
inline constexpr std::size_t kNpyMaxDims = 4;

struct NpyArray {
  std::vector<std::size_t> shape;
  std::vector<double> data;  // C order, converted to double
};

NpyArray parse_npy(const std::uint8_t* bytes, std::size_t size);
NpyArray read_npy_file(const std::filesystem::path& path);

}  // namespace tofmat
