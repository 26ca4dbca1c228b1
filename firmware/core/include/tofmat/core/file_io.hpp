// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Whole-file reading with a size bound, and atomic replacement of a file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace tofmat {

// Reads the whole file. Throws IoError if it cannot be opened or read, and
// FormatError if it is larger than max_bytes (checked before reading).
std::vector<std::uint8_t> read_file_bounded(const std::filesystem::path& path, std::size_t max_bytes);

// Writes `bytes` to a temporary file in the same directory, fsyncs it, renames
// it over `path` and fsyncs the directory: readers see the old file or the new
// one, never a partial one. On failure the old file is untouched and the
// temporary file is removed. The temporary is unnamed (O_TMPFILE) until it is
// complete, so a writer killed mid-write leaves nothing behind; where the file
// system has no O_TMPFILE it is ".NAME.tmp.XXXXXX", locked while written, and
// the next write of `path` removes those no writer holds. Throws IoError.
void write_file_atomic(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes);

}  // namespace tofmat
