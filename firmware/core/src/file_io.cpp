// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Reading a whole file under a size bound, and replacing a file atomically (write to a temporary, fsync, rename).
#include "tofmat/core/file_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <string>
#include <system_error>

#include "tofmat/core/error.hpp"

namespace tofmat {
namespace {

[[noreturn]] void io_fail(const std::string& what, const std::filesystem::path& path, int err) {
  throw IoError(what + " " + path.string() + ": " + std::generic_category().message(err), err);
}

// Closes the descriptor on every path out of a function.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

std::vector<std::uint8_t> read_file_bounded(const std::filesystem::path& path, std::size_t max_bytes) {
  // O_NONBLOCK: opening a FIFO (or a device) returns at once instead of
  // waiting for a writer; it is then refused as not a regular file.
  Fd f{::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY)};
  if (f.fd < 0) io_fail("cannot open", path, errno);
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) io_fail("cannot stat", path, errno);
  if (!S_ISREG(st.st_mode))
    throw IoError("not a regular file: " + path.string(), S_ISDIR(st.st_mode) ? EISDIR : EINVAL);
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size > max_bytes) {
    throw FormatError(path.string() + ": file is " + std::to_string(size) + " bytes, more than the " +
                      std::to_string(max_bytes) + "-byte limit for this kind of file");
  }
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(size));
  std::size_t got = 0;
  while (got < buf.size()) {
    const ssize_t n = ::read(f.fd, buf.data() + got, buf.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) io_fail("cannot read", path, errno);
    if (n == 0) break;  // shrank while reading: parse what we have, the parser reports truncation
    got += static_cast<std::size_t>(n);
  }
  buf.resize(got);
  return buf;
}

void write_file_atomic(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  std::string tmpl = (dir / ("." + path.filename().string() + ".tmp.XXXXXX")).string();
  Fd f{::mkstemp(tmpl.data())};
  if (f.fd < 0) io_fail("cannot create a temporary file in", dir, errno);
  const std::filesystem::path tmp(tmpl);
  auto abandon = [&](const char* what) {
    const int err = errno;
    ::unlink(tmp.c_str());
    io_fail(what, tmp, err);
  };
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(f.fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) abandon("cannot write");
    done += static_cast<std::size_t>(n);
  }
  if (::fchmod(f.fd, 0644) != 0) abandon("cannot set permissions of");
  if (::fsync(f.fd) != 0) abandon("cannot fsync");
  if (::close(f.fd) != 0) {
    f.fd = -1;
    abandon("cannot close");
  }
  f.fd = -1;
  if (::rename(tmp.c_str(), path.c_str()) != 0) abandon("cannot rename into place");
  // Make the rename itself durable.
  Fd d{::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (d.fd >= 0) ::fsync(d.fd);
}

}  // namespace tofmat
