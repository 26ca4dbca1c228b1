# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# The box's Debian package (tofmatd), built by CPack from the install rules
# below: `make package` runs it in the amd64 build and the aarch64 cross
# build. Included by the top-level CMakeLists.txt when tofmatd is built and the
# build is not the Python SDK's (whose wheel carries its own copy of tofmatd).
#
#   /usr/sbin/tofmatd                            the daemon
#   /etc/tofmat/tofmatd.toml                     configuration (a conffile)
#   /lib/systemd/system/tofmatd.service          the sandboxed service
#   /lib/udev/rules.d/90-tofmat-kinect2.rules    the camera for group plugdev
#   /usr/share/metainfo/tofmatd.metainfo.xml     AppStream: the camera's USB IDs
#   /usr/share/tofmat/tables/tanaka2017.tmx      the default exemplar table
#   /usr/share/tofmat/sim/                       the simulator's data (--source sim: the box's self-test)
#   /usr/share/man/man8/tofmatd.8.gz, man5/tofmatd.toml.5.gz
#   /usr/share/doc/tofmatd/{copyright,changelog.gz}
#
# TOFMAT_PACKAGE_TABLE names the table file to ship (make package builds it
# from the real database with `tofmat table import`); without it `cpack`
# refuses to run.
set(TOFMAT_PACKAGE_TABLE "" CACHE FILEPATH "The .tmx exemplar table the package installs as its default")
set(_pkg ${PROJECT_SOURCE_DIR}/firmware/daemon/package)
# (.invalid, RFC 2606: the project has no public maintainer address yet)
set(TOFMAT_PACKAGE_MAINTAINER "tofmat developers <developers@tofmat.invalid>" CACHE STRING "Maintainer field of the package")

install(TARGETS tofmatd RUNTIME DESTINATION sbin)
install(FILES ${PROJECT_SOURCE_DIR}/firmware/daemon/tofmatd.toml DESTINATION /etc/tofmat)
install(FILES ${PROJECT_SOURCE_DIR}/firmware/daemon/systemd/tofmatd.service DESTINATION /lib/systemd/system)
install(FILES ${PROJECT_SOURCE_DIR}/firmware/kinect/udev/90-tofmat-kinect2.rules DESTINATION /lib/udev/rules.d)
install(FILES ${_pkg}/tofmatd.metainfo.xml DESTINATION share/metainfo)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/firmware/sim/data/ DESTINATION share/tofmat/sim)
if(TOFMAT_PACKAGE_TABLE)
  install(FILES ${TOFMAT_PACKAGE_TABLE} DESTINATION share/tofmat/tables RENAME tanaka2017.tmx)
else()
  install(CODE "message(FATAL_ERROR \"no default table: configure with -DTOFMAT_PACKAGE_TABLE=<file.tmx> (make package does)\")")
endif()

# Man pages and the changelog, compressed as Debian wants them (gzip -n: no
# name or time stamp inside, so the package is reproducible).
set(_gz ${CMAKE_CURRENT_BINARY_DIR}/package-gz)
string(TIMESTAMP _today "%a, %d %b %Y 00:00:00 +0000" UTC)
file(WRITE ${_gz}/changelog
     "tofmatd (${PROJECT_VERSION}) unstable; urgency=medium\n\n"
     "  * Release ${PROJECT_VERSION}; see CHANGELOG.md in the source for what changed.\n\n"
     " -- ${TOFMAT_PACKAGE_MAINTAINER}  ${_today}\n")
set(_gz_files)
foreach(pair "docs/man/tofmatd.8|tofmatd.8.gz" "docs/man/tofmatd.toml.5|tofmatd.toml.5.gz" "CHANGELOG.md|changelog.upstream.gz")
  string(REPLACE "|" ";" pair "${pair}")
  list(GET pair 0 src)
  list(GET pair 1 out)
  add_custom_command(OUTPUT ${_gz}/${out} COMMAND gzip -9nc ${PROJECT_SOURCE_DIR}/${src} > ${_gz}/${out}
                     DEPENDS ${PROJECT_SOURCE_DIR}/${src} VERBATIM)
  list(APPEND _gz_files ${_gz}/${out})
endforeach()
add_custom_command(OUTPUT ${_gz}/changelog.gz COMMAND gzip -9nc ${_gz}/changelog > ${_gz}/changelog.gz
                   DEPENDS ${_gz}/changelog VERBATIM)
# (built by `make package`, not by every build)
add_custom_target(tofmat_package_docs DEPENDS ${_gz_files} ${_gz}/changelog.gz)
install(FILES ${_gz}/tofmatd.8.gz DESTINATION share/man/man8)
install(FILES ${_gz}/tofmatd.toml.5.gz DESTINATION share/man/man5)
install(FILES ${_pkg}/copyright ${_gz}/changelog.gz ${_gz}/changelog.upstream.gz DESTINATION share/doc/tofmatd)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME tofmatd)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_PACKAGE_CONTACT "${TOFMAT_PACKAGE_MAINTAINER}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "material labels from a Time-of-Flight camera (daemon)")
# The extended description (CPack puts the summary above it as the synopsis).
string(CONCAT CPACK_DEBIAN_PACKAGE_DESCRIPTION
       "tofmatd drives a Kinect v2 over USB, reads how the camera's depth is\n"
       "distorted by the material in front of it (Tanaka et al., CVPR 2017) and\n"
       "serves material labels, label maps and depth images over a Unix socket\n"
       "(or TCP with a token) to the tofmat Python SDK.\n"
       ".\n"
       "This package holds the daemon, its sandboxed systemd service, a udev rule\n"
       "for the camera, the default exemplar table of 29 materials and the\n"
       "simulated camera used for the box's self-test.")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # tofmatd_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
if(CMAKE_CROSSCOMPILING AND CMAKE_SYSTEM_PROCESSOR STREQUAL "aarch64")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)
endif()
# Library dependencies from the binary (dpkg-shlibdeps; for the cross build,
# make package sets DEB_HOST_ARCH so it reads the arm64 libraries' data).
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser, init-system-helpers (>= 1.52)")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA ${_pkg}/postinst ${_pkg}/prerm ${_pkg}/postrm ${_pkg}/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_STRIP_FILES ON)
set(CPACK_OUTPUT_FILE_PREFIX ${CMAKE_BINARY_DIR}/packages)
include(CPack)
