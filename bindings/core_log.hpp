// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ core's logs (spdlog) inside the Python extension: queued by a sink, handed to Python's
// logging ("tofmat.core") with the GIL held, never written to stdout.
#pragma once

#include <string>

#include "bindings.hpp"

namespace tofmat::py {

// Hands the queued records to logging.getLogger("tofmat.core") and sets the C++ level to that
// logger's. Call with the GIL held; a binding that runs long without the GIL calls it now and then.
void forward_core_logs();

// The text of the last warning or error the core logged since the last call, and forgets it
// ("" if none): what a failed binding can add to its exception.
std::string take_last_core_problem();

}  // namespace tofmat::py
