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
// rename). The message names the path and the reason.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace tofmat
