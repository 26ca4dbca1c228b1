# Cross build for the board (aarch64 Linux: Raspberry Pi 4/5, Jetson class) with
# Debian's g++-aarch64-linux-gnu; arm64 libraries come from multiarch
# (/usr/lib/aarch64-linux-gnu). Tests run under qemu-aarch64 (user mode).
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Executables are linked statically: qemu-aarch64 then needs no arm64 loader or
# sysroot (with multiarch arm64 packages installed, `-L /usr/aarch64-linux-gnu`
# mixes the cross loader with the multiarch libc and can hang).
set(CMAKE_EXE_LINKER_FLAGS_INIT "-static")
set(ZLIB_USE_STATIC_LIBS ON)  # FindZLIB (CMake >= 3.24): libz.a
find_program(TOFMAT_QEMU_AARCH64 qemu-aarch64 REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR ${TOFMAT_QEMU_AARCH64})

# Host programs (cmake helpers), target headers and libraries.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
