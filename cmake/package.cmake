# The Debian package: `cpack -G DEB` in a build directory configured with -DCMAKE_INSTALL_PREFIX=/usr gives
# gearpulse_<version>_<arch>.deb (scripts/test_package.sh builds, installs and removes it).
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME gearpulse)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "gearpulse developers <gearpulse@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "speed pulses for a navigator from engine ripple and GPS")
set(CPACK_PACKAGE_DESCRIPTION
    "gearpulsed captures the ripple on a car's lighter socket with a sound card, tracks the engine
frequency in it, learns the scale between GPS speed and that frequency for every gear, and emits a
speed-pulse train on a PTY or a GPIO line that keeps going through GPS outages.")
# The package installs where the build was configured to: the unit's paths come from the same prefix.
set(CPACK_PACKAGING_INSTALL_PREFIX ${CMAKE_INSTALL_PREFIX})
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# systemd-sysusers and systemd-tmpfiles (systemd), deb-systemd-helper (init-system-helpers) in postinst.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "systemd, init-system-helpers (>= 1.54~)")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "gpsd")
configure_file(${PROJECT_SOURCE_DIR}/packaging/debian/conffiles.in ${PROJECT_BINARY_DIR}/packaging/conffiles
               @ONLY)
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${PROJECT_SOURCE_DIR}/packaging/debian/postinst ${PROJECT_SOURCE_DIR}/packaging/debian/prerm
    ${PROJECT_SOURCE_DIR}/packaging/debian/postrm ${PROJECT_BINARY_DIR}/packaging/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
include(CPack)
