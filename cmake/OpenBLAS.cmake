# OpenBLAS (Debian libopenblas-dev): single-precision GEMM for the LPIPS network. Debian installs the
# header and library under a per-threading-variant folder (openblas-pthread, openblas-openmp, ...) with
# alternatives links in the multiarch folders; either is found.
find_path(D2GS_CBLAS_INCLUDE_DIR cblas.h PATH_SUFFIXES openblas-pthread openblas-openmp openblas-serial openblas REQUIRED)
find_library(D2GS_OPENBLAS_LIBRARY NAMES openblas REQUIRED)
add_library(d2gs::openblas UNKNOWN IMPORTED)
set_target_properties(d2gs::openblas PROPERTIES
  IMPORTED_LOCATION "${D2GS_OPENBLAS_LIBRARY}"
  INTERFACE_INCLUDE_DIRECTORIES "${D2GS_CBLAS_INCLUDE_DIR}")
message(STATUS "OpenBLAS: ${D2GS_OPENBLAS_LIBRARY} (cblas.h in ${D2GS_CBLAS_INCLUDE_DIR})")
