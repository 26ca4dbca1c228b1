// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Helpers shared by the core test executables. Test inputs are built here by
// hand (byte by byte), never through the code under test, so a bug in a
// writer cannot hide the same bug in the matching reader.
#pragma once

#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#ifndef TOFMAT_DB_DIR
#error "TOFMAT_DB_DIR must be defined by the build (tests/cpp/CMakeLists.txt)"
#endif

namespace tofmat_test {

using Bytes = std::vector<std::uint8_t>;

inline std::filesystem::path db_dir() { return std::filesystem::path(TOFMAT_DB_DIR); }

inline std::vector<std::filesystem::path> db_files() {
  std::vector<std::filesystem::path> out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(db_dir(), ec)) {
    if (e.path().extension() == ".npy") out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The real database is ground truth: its absence is a failure, not a skip,
// so a misconfigured TOFMAT_DB_DIR can never turn into a green run.
#define ASSERT_DB_PRESENT()                                                                    \
  ASSERT_EQ(::tofmat_test::db_files().size(), 29u)                                             \
      << "the real Kinect v2 database (29 <material>.npy files) is missing or incomplete at '" \
      << ::tofmat_test::db_dir().string() << "'; set the CMake cache variable TOFMAT_DB_DIR to its folder"

inline void put_le(Bytes& b, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

inline Bytes f8_le(const std::vector<double>& v) {
  Bytes b;
  for (double x : v) {
    std::uint64_t bits;
    std::memcpy(&bits, &x, 8);
    put_le(b, bits, 8);
  }
  return b;
}

inline Bytes f4_le(const std::vector<float>& v) {
  Bytes b;
  for (float x : v) {
    std::uint32_t bits;
    std::memcpy(&bits, &x, 4);
    put_le(b, bits, 4);
  }
  return b;
}

// An .npy file as NumPy lays it out: magic, version, header length (u16 for
// 1.0, u32 for 2.0/3.0), the dict padded with spaces and ended by '\n' so the
// data starts on a 64-byte boundary, then the raw data.
inline Bytes npy_file(std::uint8_t major, std::uint8_t minor, const std::string& dict, const Bytes& data) {
  Bytes b = {0x93, 'N', 'U', 'M', 'P', 'Y', major, minor};
  const std::size_t prefix = b.size() + (major == 1 ? 2 : 4);
  std::string header = dict;
  while ((prefix + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  put_le(b, header.size(), major == 1 ? 2 : 4);
  b.insert(b.end(), header.begin(), header.end());
  b.insert(b.end(), data.begin(), data.end());
  return b;
}

// Runs f, which must throw E; returns its message (empty and a test failure otherwise).
template <class E, class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "threw the wrong exception type: " << e.what();
    return {};
  }
  ADD_FAILURE() << "did not throw";
  return {};
}

#define EXPECT_CONTAINS(haystack, needle)                          \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) \
      << "message '" << (haystack) << "' does not mention '" << (needle) << "'"

// A fresh directory, removed with its contents at scope exit.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "tofmat_test.XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

  std::vector<std::string> entries() const {
    std::vector<std::string> out;
    for (const auto& e : std::filesystem::directory_iterator(path_)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }

 private:
  std::filesystem::path path_;
};

}  // namespace tofmat_test
