// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The bounded .npy reader: header parsing of every accepted dialect, and conversion of the data to doubles.
#include "tofmat/core/npy.hpp"

#include <cctype>
#include <cstring>
#include <string>
#include <string_view>

#include "tofmat/core/byte_reader.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/file_io.hpp"

namespace tofmat {
namespace {

[[noreturn]] void fail(const std::string& msg) { throw FormatError("npy: " + msg); }

// The header is a Python dict literal. We parse exactly the subset NumPy
// writes (string keys; string, bool and int-tuple values; Python 2 `L` suffix
// on ints; optional trailing commas) and nothing more.
class HeaderParser {
 public:
  explicit HeaderParser(std::string_view text) : s_(text) {}

  struct Header {
    std::string descr;
    bool fortran_order = false;
    std::vector<std::size_t> shape;
  };

  Header parse() {
    Header h;
    bool have_descr = false, have_order = false, have_shape = false;
    expect('{');
    while (true) {
      skip_ws();
      if (peek() == '}') break;
      const std::string key = quoted();
      expect(':');
      if (key == "descr") {
        if (have_descr) fail("header repeats key 'descr'");
        h.descr = quoted();
        have_descr = true;
      } else if (key == "fortran_order") {
        if (have_order) fail("header repeats key 'fortran_order'");
        h.fortran_order = boolean();
        have_order = true;
      } else if (key == "shape") {
        if (have_shape) fail("header repeats key 'shape'");
        h.shape = tuple();
        have_shape = true;
      } else {
        fail("header has unknown key '" + key + "'");
      }
      skip_ws();
      if (peek() == ',') {
        ++pos_;
        continue;
      }
      if (peek() != '}') fail("header: expected ',' or '}' at offset " + std::to_string(pos_));
    }
    ++pos_;
    skip_ws();
    if (pos_ != s_.size()) fail("header has trailing characters after the dict");
    if (!have_descr || !have_order || !have_shape) fail("header lacks one of 'descr', 'fortran_order', 'shape'");
    return h;
  }

 private:
  char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
  void skip_ws() {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n')) ++pos_;
  }
  void expect(char c) {
    skip_ws();
    if (peek() != c) fail(std::string("header: expected '") + c + "' at offset " + std::to_string(pos_));
    ++pos_;
  }
  std::string quoted() {
    skip_ws();
    const char q = peek();
    if (q != '\'' && q != '"') fail("header: expected a quoted string at offset " + std::to_string(pos_));
    const std::size_t end = s_.find(q, pos_ + 1);
    if (end == std::string_view::npos) fail("header: unterminated string");
    std::string out(s_.substr(pos_ + 1, end - pos_ - 1));
    pos_ = end + 1;
    return out;
  }
  bool boolean() {
    skip_ws();
    if (s_.substr(pos_, 4) == "True") {
      pos_ += 4;
      return true;
    }
    if (s_.substr(pos_, 5) == "False") {
      pos_ += 5;
      return false;
    }
    fail("header: 'fortran_order' must be True or False");
  }
  std::size_t integer() {
    skip_ws();
    if (!std::isdigit(static_cast<unsigned char>(peek()))) fail("header: shape must hold non-negative integers");
    std::size_t v = 0;
    while (std::isdigit(static_cast<unsigned char>(peek()))) {
      if (v > kNpyMaxElements) fail("header: shape dimension is absurdly large");
      v = v * 10 + static_cast<std::size_t>(peek() - '0');
      ++pos_;
    }
    if (peek() == 'L' || peek() == 'l') ++pos_;  // Python 2 long suffix
    return v;
  }
  std::vector<std::size_t> tuple() {
    std::vector<std::size_t> dims;
    expect('(');
    while (true) {
      skip_ws();
      if (peek() == ')') break;
      if (dims.size() == kNpyMaxDims) fail("array has more than " + std::to_string(kNpyMaxDims) + " dimensions");
      dims.push_back(integer());
      skip_ws();
      if (peek() == ',') {
        ++pos_;
        continue;
      }
      if (peek() != ')') fail("header: expected ',' or ')' in shape");
    }
    ++pos_;
    return dims;
  }

  std::string_view s_;
  std::size_t pos_ = 0;
};

}  // namespace

NpyArray parse_npy(const std::uint8_t* bytes, std::size_t size) {
  ByteReader in(bytes, size, "npy");
  static constexpr char kMagic[] = "\x93NUMPY";
  if (std::memcmp(in.take(6, "magic"), kMagic, 6) != 0) fail("bad magic (not a .npy file)");
  const std::uint8_t major = in.u8("version");
  const std::uint8_t minor = in.u8("version");
  if (major < 1 || major > 3 || minor != 0) {
    fail("unsupported format version " + std::to_string(major) + "." + std::to_string(minor) +
         " (supported: 1.0, 2.0, 3.0)");
  }
  const std::size_t header_len = major == 1 ? in.u16("header length") : in.u32("header length");
  if (header_len > kNpyMaxHeaderBytes) fail("header length " + std::to_string(header_len) + " exceeds the limit");
  const auto* htext = in.take(header_len, "header");
  const std::string_view header(reinterpret_cast<const char*>(htext), header_len);
  for (char c : header) {
    if (static_cast<unsigned char>(c) >= 0x80 || (c < 0x20 && c != '\n' && c != '\t')) {
      fail("header contains non-text bytes");
    }
  }
  const auto h = HeaderParser(header).parse();

  std::size_t elem_size = 0;
  if (h.descr == "<f8") {
    elem_size = 8;
  } else if (h.descr == "<f4") {
    elem_size = 4;
  } else {
    fail("unsupported dtype '" + h.descr + "' (expected '<f8' or '<f4')");
  }
  if (h.fortran_order) fail("Fortran-ordered arrays are not supported");
  if (h.shape.empty()) fail("0-dimensional arrays are not supported");

  std::size_t count = 1;
  for (std::size_t d : h.shape) {
    if (d != 0 && count > kNpyMaxElements / d) fail("shape is absurdly large");
    count *= d;
  }
  if (count > kNpyMaxElements) fail("shape is absurdly large");

  const std::size_t data_bytes = count * elem_size;
  if (in.remaining() != data_bytes) {
    fail("data size " + std::to_string(in.remaining()) + " bytes does not match shape and dtype (" +
         std::to_string(data_bytes) + " bytes)" + (in.remaining() < data_bytes ? ": truncated" : ""));
  }
  const std::uint8_t* raw = in.take(data_bytes, "data");

  NpyArray out;
  out.shape = h.shape;
  out.data.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    if (elem_size == 8) {
      std::uint64_t bits = 0;
      for (int b = 7; b >= 0; --b) bits = (bits << 8) | raw[i * 8 + static_cast<std::size_t>(b)];
      std::memcpy(&out.data[i], &bits, 8);
    } else {
      std::uint32_t bits = 0;
      for (int b = 3; b >= 0; --b) bits = (bits << 8) | raw[i * 4 + static_cast<std::size_t>(b)];
      float f;
      std::memcpy(&f, &bits, 4);
      out.data[i] = f;
    }
  }
  return out;
}

NpyArray read_npy_file(const std::filesystem::path& path) {
  const std::size_t limit = 16 + kNpyMaxHeaderBytes + kNpyMaxElements * 8;
  const auto bytes = read_file_bounded(path, limit);
  try {
    return parse_npy(bytes.data(), bytes.size());
  } catch (const FormatError& e) {
    throw FormatError(path.string() + ": " + e.what());
  }
}

}  // namespace tofmat
