# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Cross build for the board (aarch64 Linux, Debian 12: Raspberry Pi 4/5, Jetson
# class) with Debian's g++-aarch64-linux-gnu; arm64 libraries come from
# multiarch (/usr/lib/aarch64-linux-gnu, `dpkg --add-architecture arm64`), the
# same packages the board installs. Programs run here under qemu-aarch64.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Executables link dynamically against the multiarch libraries, as they run on
# the board (Debian ships spdlog and fmt for arm64 as shared libraries only).
# The cross linker looks in its own sysroot; the libraries' own dependencies
# (OpenCV's TBB, ...) are found through -rpath-link.
set(CMAKE_EXE_LINKER_FLAGS_INIT "-Wl,-rpath-link,/usr/lib/aarch64-linux-gnu:/lib/aarch64-linux-gnu")
set(CMAKE_SHARED_LINKER_FLAGS_INIT "-Wl,-rpath-link,/usr/lib/aarch64-linux-gnu:/lib/aarch64-linux-gnu")
# qemu-aarch64 runs them with the arm64 loader and libc of multiarch
# (/lib/ld-linux-aarch64.so.1, libc6:arm64), found from / (no -L: the cross
# toolchain's own loader in /usr/aarch64-linux-gnu mixed with the multiarch
# libc can hang).
find_program(TOFMAT_QEMU_AARCH64 qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR ${TOFMAT_QEMU_AARCH64})

# pkg-config (libusb) reads the arm64 packages' .pc files, never the host's.
set(ENV{PKG_CONFIG_LIBDIR} "/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_PATH} "")
# Our own libraries are static and the system's live in the board's default
# folders: no run-time search path in the programs.
set(CMAKE_SKIP_RPATH ON)

# Host programs (cmake helpers), target headers and libraries.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
