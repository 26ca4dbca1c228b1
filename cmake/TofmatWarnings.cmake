# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Warnings as errors on our own targets only (never on third-party code).
function(tofmat_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
                                           -Wnon-virtual-dtor -Wold-style-cast -Werror)
endfunction()
