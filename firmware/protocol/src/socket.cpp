// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Socket helpers: addresses, listening and connecting on Unix and TCP sockets, timed writes, and the wake-up eventfd.
#include "tofmat/protocol/socket.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <system_error>

namespace tofmat::protocol {
namespace {

[[noreturn]] void fail(const std::string& what) {
  const int e = errno;
  throw SocketError(what + ": " + std::generic_category().message(e), e);
}

sockaddr_un unix_address(const std::string& path) {
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof(sa.sun_path))
    throw SocketError(
        "socket path \"" + path + "\" is empty or longer than " + std::to_string(sizeof(sa.sun_path) - 1) + " bytes",
        ENAMETOOLONG);
  std::memcpy(sa.sun_path, path.c_str(), path.size() + 1);
  return sa;
}

sockaddr_in tcp_address(const std::string& host, std::uint16_t port) {
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(port);
  const std::string h = host == "localhost" ? "127.0.0.1" : host;
  if (inet_pton(AF_INET, h.c_str(), &sa.sin_addr) != 1)
    throw SocketError("\"" + host + "\" is not an IPv4 address (or localhost)", EINVAL);
  return sa;
}

bool poll_one(int fd, short events, int timeout_ms) {
  pollfd p{fd, events, 0};
  for (;;) {
    const int r = ::poll(&p, 1, timeout_ms);
    if (r > 0) return true;
    if (r == 0) return false;
    if (errno != EINTR) fail("poll");
  }
}

}  // namespace

WakeFd::WakeFd() : fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {
  if (!fd_) throw SocketError("eventfd failed", errno);
}

void WakeFd::wake() {
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n = ::write(fd_.get(), &one, sizeof one);  // (full: a wake is pending anyway)
}

void WakeFd::drain() {
  std::uint64_t v;
  [[maybe_unused]] const auto n = ::read(fd_.get(), &v, sizeof v);
}

Fd::~Fd() { reset(); }

Fd& Fd::operator=(Fd&& o) noexcept {
  if (this != &o) {
    reset();
    fd_ = o.release();
  }
  return *this;
}

void Fd::reset() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

std::string Address::describe() const { return tcp ? host + ":" + std::to_string(port) : path; }

Address parse_address(const std::string& text) {
  Address a;
  if (text.rfind("unix:", 0) == 0) {
    a.path = text.substr(5);
  } else {
    const auto colon = text.rfind(':');
    if (colon == std::string::npos || text.find('/') != std::string::npos) {
      a.path = text;
    } else {
      a.tcp = true;
      a.host = text.substr(0, colon);
      const std::string port = text.substr(colon + 1);
      char* end = nullptr;
      const unsigned long p = std::strtoul(port.c_str(), &end, 10);
      if (port.empty() || *end != '\0' || p == 0 || p > 65535)
        throw std::invalid_argument("bad port in address \"" + text + "\" (want host:port, port 1..65535)");
      a.port = static_cast<std::uint16_t>(p);
      if (a.host.empty()) a.host = "127.0.0.1";
    }
  }
  if (!a.tcp && a.path.empty()) throw std::invalid_argument("empty socket path");
  return a;
}

void set_nonblocking(int fd) {
  const int flags = ::fcntl(fd, F_GETFL, 0);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) < 0) fail("fcntl(O_NONBLOCK)");
}

Fd listen_unix(const std::string& path, unsigned mode) {
  const sockaddr_un sa = unix_address(path);
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode))
      throw SocketError("\"" + path + "\" exists and is not a socket; not replacing it", EEXIST);
    // A socket file: replace it only when it is ours and nothing listens on
    // it (ECONNREFUSED). Any other answer (a connection, a full backlog, no
    // permission) may be a live daemon, perhaps another user's: left alone.
    if (st.st_uid != ::geteuid())
      throw SocketError(
          "\"" + path + "\" is a socket of another user (uid " + std::to_string(st.st_uid) + "); not replacing it",
          EEXIST);
    // (Non-blocking: a live daemon's full backlog answers EAGAIN at once instead of holding us.)
    Fd probe(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
    if (!probe) fail("socket(AF_UNIX)");
    if (::connect(probe.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa) == 0)
      throw SocketError("another daemon is listening on \"" + path + "\"", EADDRINUSE);
    if (errno != ECONNREFUSED)
      throw SocketError("cannot tell whether a daemon listens on \"" + path + "\"; not replacing it", errno);
    ::unlink(path.c_str());
  }
  Fd fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
  if (!fd) fail("socket(AF_UNIX)");
  // Create the file with no access and open it up to mode afterwards, so
  // there is no moment where it is wider than asked.
  const mode_t old = ::umask(0777);
  const int r = ::bind(fd.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa);
  ::umask(old);
  if (r != 0) fail("bind(\"" + path + "\")");
  if (::chmod(path.c_str(), static_cast<mode_t>(mode)) != 0) fail("chmod(\"" + path + "\")");
  // A short backlog: a server that paces its accepts (tofmatd: while a
  // client connects in a loop) then holds a new client for at most this
  // many accepts; clients wait for room in connect (connect_to).
  if (::listen(fd.get(), kUnixBacklog) != 0) fail("listen(\"" + path + "\")");
  return fd;
}

Fd listen_tcp(const std::string& host, std::uint16_t port) {
  const sockaddr_in sa = tcp_address(host, port);
  Fd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
  if (!fd) fail("socket(AF_INET)");
  const int one = 1;
  ::setsockopt(fd.get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0)
    fail("bind(" + host + ":" + std::to_string(port) + ")");
  if (::listen(fd.get(), SOMAXCONN) != 0) fail("listen");
  return fd;
}

std::uint16_t local_port(int fd) {
  sockaddr_in sa{};
  socklen_t len = sizeof sa;
  if (::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len) != 0) fail("getsockname");
  return ntohs(sa.sin_port);
}

Fd connect_to(const Address& address, int timeout_ms) {
  Fd fd;
  int r = 0;
  if (address.tcp) {
    const sockaddr_in sa = tcp_address(address.host, address.port);
    fd = Fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
    if (!fd) fail("socket(AF_INET)");
    const int one = 1;
    ::setsockopt(fd.get(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    r = ::connect(fd.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa);
  } else {
    // A Unix socket connects at once or not at all: with a full backlog
    // (the server is busy, or paces its accepts) a blocking connect sleeps
    // until the server accepts one, when the kernel wakes the waiters, up
    // to SO_SNDTIMEO. Polling for room instead would lose every time to a
    // client connecting in a loop.
    const sockaddr_un sa = unix_address(address.path);
    fd = Fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    if (!fd) fail("socket(AF_UNIX)");
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      const auto left_us =
          std::chrono::duration_cast<std::chrono::microseconds>(deadline - std::chrono::steady_clock::now()).count();
      if (left_us <= 0)
        throw SocketError("connect to " + address.describe() + ": timed out (its backlog stayed full)", ETIMEDOUT);
      timeval tv{};
      tv.tv_sec = static_cast<time_t>(left_us / 1'000'000);
      tv.tv_usec = static_cast<suseconds_t>(left_us % 1'000'000);
      if (::setsockopt(fd.get(), SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv) != 0) fail("setsockopt(SO_SNDTIMEO)");
      if (::connect(fd.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa) == 0) break;
      if (errno != EINTR && errno != EAGAIN) fail("connect to " + address.describe());
    }
    set_nonblocking(fd.get());
    return fd;
  }
  if (r != 0) {
    if (errno != EINPROGRESS) fail("connect to " + address.describe());
    if (!poll_one(fd.get(), POLLOUT, timeout_ms))
      throw SocketError("connect to " + address.describe() + ": timed out", ETIMEDOUT);
    int err = 0;
    socklen_t len = sizeof err;
    ::getsockopt(fd.get(), SOL_SOCKET, SO_ERROR, &err, &len);
    if (err != 0) {
      errno = err;
      fail("connect to " + address.describe());
    }
  }
  return fd;
}

bool wait_readable(int fd, int timeout_ms) { return poll_one(fd, POLLIN, timeout_ms); }
bool wait_writable(int fd, int timeout_ms) { return poll_one(fd, POLLOUT, timeout_ms); }

void write_all(int fd, const std::uint8_t* data, std::size_t size, int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (size > 0) {
    const ssize_t n = ::send(fd, data, size, MSG_NOSIGNAL);
    if (n > 0) {
      data += n;
      size -= static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) fail("send");
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0 || !wait_writable(fd, static_cast<int>(left.count())))
      throw SocketError("send: timed out", ETIMEDOUT);
  }
}

std::uint64_t monotonic_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

void poll_until(::pollfd* fds, std::size_t count, std::uint64_t until_ns) {
  const std::uint64_t now = monotonic_ns(), wait = until_ns > now ? until_ns - now : 0;
  timespec ts{static_cast<time_t>(wait / 1'000'000'000ull), static_cast<long>(wait % 1'000'000'000ull)};
  if (::ppoll(fds, static_cast<nfds_t>(count), &ts, nullptr) < 0 && errno != EINTR)
    throw SocketError(std::string("poll failed: ") + std::generic_category().message(errno), errno);
}

}  // namespace tofmat::protocol
