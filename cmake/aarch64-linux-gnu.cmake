# Cross-compiling for 64-bit Arm Linux with Debian's cross compiler (g++-aarch64-linux-gnu)
# against the arm64 packages installed beside the native ones (dpkg multiarch: libraries
# in /usr/lib/aarch64-linux-gnu, headers shared in /usr/include). Programs built with it
# run on this machine under qemu-user. scripts/cross-aarch64.sh sets it all up.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

# Highway's NEON target uses the AES instructions; GCC 12 refuses to inline them into
# code built for plain armv8-a ("target specific option mismatch").
set(CMAKE_CXX_FLAGS_INIT "-march=armv8-a+crypto")

# Find the arm64 packages, never the native ones: CMake configs through the library
# architecture above, pkg-config files only from the arm64 directory.
set(ENV{PKG_CONFIG_LIBDIR} "/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_PATH} "")

# ctest and gtest_discover_tests run the test programs through qemu-user; the arm64
# dynamic loader and libc come from the multiarch packages under / (libc6:arm64).
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64-static -L /)
