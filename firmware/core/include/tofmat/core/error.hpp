// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Error types shared by every stage. Bindings map them to Python exceptions:
// FormatError -> tofmat.FormatError (a ValueError), IoError -> OSError,
// std::invalid_argument -> ValueError.
#pragma once

#include <stdexcept>
#include <string>

namespace tofmat {

// Bytes that came from outside (a file, later the USB stream or a socket) do
// not follow the format they claim to be in. The message names the problem.
class FormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The operating system refused an operation on a file (open, read, write,
// rename), or a path is not what it must be. The message names the path and
// the reason; error_number() is the errno that says which (0: none applies),
// so the bindings raise FileNotFoundError, PermissionError and the like.
class IoError : public std::runtime_error {
 public:
  explicit IoError(const std::string& what, int error_number = 0)
      : std::runtime_error(what), error_number_(error_number) {}
  int error_number() const noexcept { return error_number_; }

 private:
  int error_number_;
};

}  // namespace tofmat
