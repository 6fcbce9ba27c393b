# FindSuiteSparse.cmake -- CHOLMOD from Debian's SuiteSparse 5.12, which ships no CMake
# package of its own.  Defines the IMPORTED target SuiteSparse::CHOLMOD.
#
# Only CHOLMOD is needed; its dependencies (AMD, COLAMD, CAMD, CCOLAMD, SuiteSparse_config,
# BLAS/LAPACK) are linked through the shared library's own DT_NEEDED entries on Debian,
# but we add SuiteSparse_config explicitly since cholmod.h uses its symbols.
include(FindPackageHandleStandardArgs)

find_path(SuiteSparse_INCLUDE_DIR NAMES cholmod.h PATH_SUFFIXES suitesparse)
find_library(SuiteSparse_CHOLMOD_LIBRARY NAMES cholmod)
find_library(SuiteSparse_CONFIG_LIBRARY NAMES suitesparseconfig)

if(SuiteSparse_INCLUDE_DIR AND EXISTS "${SuiteSparse_INCLUDE_DIR}/cholmod_core.h")
  file(STRINGS "${SuiteSparse_INCLUDE_DIR}/cholmod_core.h" _cholmod_ver
       REGEX "#define CHOLMOD_(MAIN|SUB)_VERSION")
  string(REGEX REPLACE ".*MAIN_VERSION[ \t]+([0-9]+).*" "\\1" _maj "${_cholmod_ver}")
  string(REGEX REPLACE ".*SUB_VERSION[ \t]+([0-9]+).*" "\\1" _min "${_cholmod_ver}")
  set(SuiteSparse_VERSION "${_maj}.${_min}")
endif()

find_package_handle_standard_args(SuiteSparse
  REQUIRED_VARS SuiteSparse_CHOLMOD_LIBRARY SuiteSparse_CONFIG_LIBRARY SuiteSparse_INCLUDE_DIR
  VERSION_VAR SuiteSparse_VERSION
  REASON_FAILURE_MESSAGE "install Debian's libsuitesparse-dev")

if(SuiteSparse_FOUND AND NOT TARGET SuiteSparse::CHOLMOD)
  add_library(SuiteSparse::CHOLMOD UNKNOWN IMPORTED)
  set_target_properties(SuiteSparse::CHOLMOD PROPERTIES
    IMPORTED_LOCATION "${SuiteSparse_CHOLMOD_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${SuiteSparse_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${SuiteSparse_CONFIG_LIBRARY}")
endif()
mark_as_advanced(SuiteSparse_INCLUDE_DIR SuiteSparse_CHOLMOD_LIBRARY SuiteSparse_CONFIG_LIBRARY)
