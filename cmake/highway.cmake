# Highway, for the SIMD kernels (pipeline/sgm, pipeline/resample): its CMake package where
# installed, else pkg-config. Sets STEREOD_HWY_TARGET in the including directory, where
# the imported target is visible.
find_package(HWY 1.0 QUIET CONFIG)
if(NOT HWY_FOUND)
  pkg_check_modules(HWY REQUIRED IMPORTED_TARGET libhwy)
  set(STEREOD_HWY_TARGET PkgConfig::HWY)
else()
  set(STEREOD_HWY_TARGET hwy::hwy)
endif()
