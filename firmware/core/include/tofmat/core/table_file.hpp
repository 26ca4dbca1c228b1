// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The compact exemplar table file (.tmx), format versions 1.0 to 1.3; the
// layout is documented in docs/table-format.md. Values are int16 multiples of
// a power-of-two quantisation step, INT16_MIN marks a missing element, 1.1
// adds each material's bin noise per row (float32), 1.2 each material's depth
// distortion on a grid of depths (float32), 1.3 the table's own calibration
// (session prior, temperatures, open-set thresholds), and a CRC-32 over everything
// before it guards the whole file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

inline constexpr char kTableMagic[8] = {'T', 'O', 'F', 'M', 'A', 'T', 'B', 'L'};
inline constexpr std::uint16_t kTableVersionMajor = 1;
// The newest minor this build reads and writes: 1.3 (the calibration).
// The writer uses the oldest minor that holds the table (1.0 without noise,
// distortion or calibration, 1.1 with noise only, 1.2 with a distortion), so
// older readers still load it.
inline constexpr std::uint16_t kTableVersionMinor = 3;
inline constexpr std::int16_t kTableMissing = INT16_MIN;
inline constexpr std::int16_t kTableMaxAbs = 32767;
// Upper bound on a table file: 4096 materials x 16 rows x 65535 bins would be
// 8 GiB, far beyond any real table; refuse anything over this before reading.
inline constexpr std::size_t kTableMaxFileBytes = 64u * 1024u * 1024u;

// The smallest power-of-two step (in mm) that represents every value of the
// table in [-32767, 32767] steps. Values round to the nearest step, so the
// round-trip error is at most half a step.
double choose_quant_step_mm(const ExemplarTable& table);

std::vector<std::uint8_t> encode_table(const ExemplarTable& table);
// Throws FormatError naming the problem: bad magic, unsupported version,
// truncation, oversized dimensions, checksum mismatch, inconsistent content.
ExemplarTable decode_table(const std::uint8_t* bytes, std::size_t size);

// Atomic: the previous file at `path` stays intact if anything fails.
void save_table(const ExemplarTable& table, const std::filesystem::path& path);
ExemplarTable load_table(const std::filesystem::path& path);

}  // namespace tofmat
