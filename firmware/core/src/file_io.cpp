// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Reading a whole file under a size bound, and replacing a file atomically (write to a temporary, fsync, rename).
#include "tofmat/core/file_io.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
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

// A writer's temporary of `path`: ".NAME.tmp.XXXXXX" beside it.
static std::string temporary_prefix(const std::filesystem::path& path) {
  return "." + path.filename().string() + ".tmp.";
}

// Removes the temporaries of `path` that a writer killed mid-write left
// behind (SIGKILL, a power cut): those no live writer holds locked (a writer
// locks its temporary from the moment it has one) and untouched for 2 s (a
// writer between mkstemp and its lock is younger than that).
static void remove_stale_temporaries(const std::filesystem::path& dir, const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  const std::string prefix = temporary_prefix(path);
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() != prefix.size() + 6 || name.compare(0, prefix.size(), prefix) != 0) continue;
    std::error_code sec;
    if (!fs::is_regular_file(fs::symlink_status(it->path(), sec)) || sec) continue;
    const auto age = fs::file_time_type::clock::now() - fs::last_write_time(it->path(), sec);
    if (sec || age < std::chrono::seconds(2)) continue;
    Fd f{::open(it->path().c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK | O_NOCTTY)};
    if (f.fd >= 0 && ::flock(f.fd, LOCK_EX | LOCK_NB) == 0) ::unlink(it->path().c_str());
  }
}

void write_file_atomic(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  remove_stale_temporaries(dir, path);
  // The bytes go to an unnamed file (O_TMPFILE) where the file system has
  // them: a writer killed while writing leaves nothing. It gets its
  // temporary name only once written and synced, for the rename; elsewhere
  // a named temporary from the start, locked while it is written.
  std::string tmpl = (dir / (temporary_prefix(path) + "XXXXXX")).string();
  bool unnamed = true;
  Fd f{::open(dir.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600)};
  if (f.fd < 0) {
    unnamed = false;
    f.fd = ::mkstemp(tmpl.data());
    if (f.fd < 0) io_fail("cannot create a temporary file in", dir, errno);
  }
  ::flock(f.fd, LOCK_EX);  // (a lock on the file itself: held by this writer until it is renamed or removed)
  std::filesystem::path tmp(tmpl);
  auto abandon = [&](const char* what) {
    const int err = errno;
    if (!unnamed) ::unlink(tmp.c_str());
    io_fail(what, unnamed ? dir : tmp, err);
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
  if (unnamed) {
    // A name for the unnamed file: mkstemp's name, taken and given back, then linked to it.
    for (int attempt = 0;; ++attempt) {
      tmpl = (dir / (temporary_prefix(path) + "XXXXXX")).string();
      Fd probe{::mkstemp(tmpl.data())};
      if (probe.fd < 0) abandon("cannot name a temporary file in");
      ::unlink(tmpl.c_str());
      const std::string self = "/proc/self/fd/" + std::to_string(f.fd);
      if (::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, tmpl.c_str(), AT_SYMLINK_FOLLOW) == 0) break;
      if (errno != EEXIST || attempt >= 8) abandon("cannot link the temporary file into");
    }
    tmp = tmpl;
    unnamed = false;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) abandon("cannot rename into place");
  if (::close(f.fd) != 0) {
    f.fd = -1;
    io_fail("cannot close", path, errno);
  }
  f.fd = -1;
  // Make the rename itself durable.
  Fd d{::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (d.fd >= 0) ::fsync(d.fd);
}

}  // namespace tofmat
