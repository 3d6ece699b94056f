# Installation and the Debian package (`cpack -G DEB` in a build tree; scripts/package).
#
# Installs the program to bin/ and, where the Python module is built, the loopsfm package to
# Debian's python3 path (lib/python3/dist-packages). The package's dependencies are Debian's
# runtime packages: dpkg-shlibdeps finds those of the program's and the module's libraries,
# and python3-numpy is added for the module. Build it from a tree configured with
# -DLOOPSFM_NATIVE=OFF, so it runs on any x86-64 (the matching kernels are chosen at run time).
include(GNUInstallDirs)
# `install` and cpack take the program and the module as built (scripts/package builds those
# two), instead of building every test and benchmark first.
set(CMAKE_SKIP_INSTALL_ALL_DEPENDENCY ON)
install(TARGETS loopsfm RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(FILES README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
if(loopsfm_python)
  set(LOOPSFM_PYTHON_INSTALL_DIR "lib/python3/dist-packages" CACHE STRING
      "Where `install` puts the Python package loopsfm (relative to the prefix)")
  install(TARGETS _loopsfm LIBRARY DESTINATION ${LOOPSFM_PYTHON_INSTALL_DIR}/loopsfm)
  install(FILES python/loopsfm/__init__.py python/loopsfm/_loopsfm.pyi python/loopsfm/py.typed
          DESTINATION ${LOOPSFM_PYTHON_INSTALL_DIR}/loopsfm)
endif()

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME loopsfm)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "loopsfm developers <loopsfm@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "camera poses and a sparse 3D point cloud from video, with loop closing")
string(CONCAT CPACK_PACKAGE_DESCRIPTION
    "loopsfm turns a video or an ordered image folder into camera poses and a sparse point "
    "cloud (COLMAP models, PLY, trajectories, nerfstudio and Gaussian-splatting layouts, an HTML "
    "report), finding where the camera returns with a vocabulary tree and closing the loops. "
    "The package holds the loopsfm program and the Python module (import loopsfm).")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
if(loopsfm_python)
  # The module is built for one Python version (its ABI): that version's python3.
  math(EXPR next_minor "${Python3_VERSION_MINOR} + 1")
  set(CPACK_DEBIAN_PACKAGE_DEPENDS
      "python3 (>= ${Python3_VERSION_MAJOR}.${Python3_VERSION_MINOR}), python3 (<< ${Python3_VERSION_MAJOR}.${next_minor}), python3-numpy")
endif()
include(CPack)
