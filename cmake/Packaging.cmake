# Installation (`cmake --install`) and the Debian package (CPack DEB): issue 8.
#
#   cmake --install build --prefix /usr [--strip]     # or DESTDIR=/stage cmake --install ...
#   scripts/package.sh                                # Release build in build-pkg/, then cpack
#
# Layout under the prefix (/usr for the package):
#   bin/teleop-master, bin/teleop-slave, bin/teleop-supervisor, bin/teleopctl
#   share/teleop/examples/...                  the examples/ tree
#   share/doc/teleop/README.md, share/doc/teleop/docs/*.md   (the README's links are relative)
#   lib/systemd/system/teleop-{master,slave,supervisor}.service   (TELEOP_SYSTEMD_UNIT_DIR)
#   lib/sysusers.d/teleop.conf, lib/tmpfiles.d/teleop.conf, lib/udev/rules.d/70-teleop.rules
#   share/man/man1/{teleopctl,teleop-master,teleop-slave,teleop-supervisor}.1  (help2man)
#   share/bash-completion/completions/{the same four names}
#   share/teleop/proto/teleop/v1/*.proto, share/teleop/proto/foxglove/*.proto and
#     share/teleop/proto/teleop.desc (their FileDescriptorSet, imports included)
#   lib/python3/dist-packages/teleop.<abi>.so   the Python module (TELEOP_PYTHON_INSTALL_DIR,
#     python/CMakeLists.txt), when built (TELEOP_BUILD_PYTHON)
# Nothing goes to /etc: the units read /etc/teleop/{master,slave,supervisor}.textproto, which
# the administrator writes (from the examples); the package has no conffiles.
include(GNUInstallDirs)

set(TELEOP_SYSTEMD_UNIT_DIR "lib/systemd/system" CACHE STRING
    "Where the systemd units are installed (relative to the install prefix, or absolute)")
set(TELEOP_SYSUSERS_DIR "lib/sysusers.d" CACHE STRING "Where the sysusers.d file is installed")
set(TELEOP_TMPFILES_DIR "lib/tmpfiles.d" CACHE STRING "Where the tmpfiles.d file is installed")
set(TELEOP_UDEV_RULES_DIR "lib/udev/rules.d" CACHE STRING "Where the udev rules are installed")

set(_teleop_deploy "${PROJECT_SOURCE_DIR}/deploy")

install(TARGETS teleop-master teleop-slave teleop-supervisor teleopctl
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY "${PROJECT_SOURCE_DIR}/examples/" DESTINATION ${CMAKE_INSTALL_DATADIR}/teleop/examples)
install(FILES "${PROJECT_SOURCE_DIR}/README.md" DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY "${PROJECT_SOURCE_DIR}/proto/" DESTINATION ${CMAKE_INSTALL_DATADIR}/teleop/proto
        FILES_MATCHING PATTERN "*.proto")
install(FILES "${PROJECT_BINARY_DIR}/proto/teleop.desc" DESTINATION ${CMAKE_INSTALL_DATADIR}/teleop/proto)
install(DIRECTORY "${PROJECT_SOURCE_DIR}/docs/" DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs
        FILES_MATCHING PATTERN "*.md")
install(FILES "${_teleop_deploy}/systemd/teleop-master.service"
              "${_teleop_deploy}/systemd/teleop-slave.service"
              "${_teleop_deploy}/systemd/teleop-supervisor.service"
        DESTINATION ${TELEOP_SYSTEMD_UNIT_DIR})
install(FILES "${_teleop_deploy}/sysusers.d/teleop.conf" DESTINATION ${TELEOP_SYSUSERS_DIR})
install(FILES "${_teleop_deploy}/tmpfiles.d/teleop.conf" DESTINATION ${TELEOP_TMPFILES_DIR})
install(FILES "${_teleop_deploy}/udev/70-teleop.rules" DESTINATION ${TELEOP_UDEV_RULES_DIR})
# Bash completion: one script, installed under each program's name (bash-completion loads a
# program's completion from the file of its name).
foreach(_prog teleopctl teleop-master teleop-slave teleop-supervisor)
  install(FILES "${_teleop_deploy}/bash-completion/teleopctl"
          DESTINATION ${CMAKE_INSTALL_DATADIR}/bash-completion/completions RENAME ${_prog})
endforeach()

# A man page per program, generated from its --help (scripts/make-man.sh, help2man). Not in a
# sanitizer build (its binaries are not installed) nor without help2man (install-deps.sh).
find_program(TELEOP_HELP2MAN help2man)
if(TELEOP_HELP2MAN AND NOT TELEOP_SANITIZE AND NOT CMAKE_CROSSCOMPILING)
  set(_teleop_man_dir "${PROJECT_BINARY_DIR}/man")
  set(_teleop_man_pages)
  foreach(_entry
          "teleopctl|the teleoperator's console: analyse, simulate, launch, command, replay"
          "teleop-master|the master node of a bilateral teleoperator (1 kHz real-time loop)"
          "teleop-slave|the slave node of a bilateral teleoperator (1 kHz real-time loop)"
          "teleop-supervisor|watches a teleoperator: stability, guarded changes, recording")
    string(REPLACE "|" ";" _parts "${_entry}")
    list(GET _parts 0 _prog)
    list(GET _parts 1 _desc)
    add_custom_command(
      OUTPUT "${_teleop_man_dir}/${_prog}.1"
      COMMAND ${CMAKE_COMMAND} -E make_directory "${_teleop_man_dir}"
      COMMAND "${PROJECT_SOURCE_DIR}/scripts/make-man.sh" "$<TARGET_FILE:${_prog}>"
              "${_teleop_man_dir}/${_prog}.1" "${_desc}"
      DEPENDS ${_prog} "${PROJECT_SOURCE_DIR}/scripts/make-man.sh"
      VERBATIM)
    list(APPEND _teleop_man_pages "${_teleop_man_dir}/${_prog}.1")
  endforeach()
  add_custom_target(teleop_man_pages ALL DEPENDS ${_teleop_man_pages})
  install(FILES ${_teleop_man_pages} DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)
else()
  message(STATUS "teleop: no man pages (help2man not found, or a sanitizer build)")
endif()

# The units name /usr/bin/teleop-*: say so when the binaries go elsewhere.
install(CODE [[
  if(NOT CMAKE_INSTALL_PREFIX STREQUAL "/usr")
    message(WARNING "teleop: installed under ${CMAKE_INSTALL_PREFIX}, but the systemd units "
                    "start /usr/bin/teleop-*: install with --prefix /usr to use the units")
  endif()
]])

# --- Debian package -------------------------------------------------------------------------
set(CPACK_GENERATOR "DEB")
set(CPACK_VERBATIM_VARIABLES ON)  # values reach CPackConfig.cmake unescaped
set(CPACK_PACKAGE_NAME "teleop")
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGE_VENDOR "teleop")
set(CPACK_PACKAGE_CONTACT "teleop dev <dev@teleop.invalid>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "Bilateral teleoperation daemons with stable forbidden-region virtual fixtures")
set(CPACK_PACKAGING_INSTALL_PREFIX "/usr")
# Strip the installed executables (the build keeps its debug information).
set(CPACK_STRIP_FILES ON)

set(CPACK_DEBIAN_PACKAGE_NAME "teleop")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # teleop_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CPACK_PACKAGE_CONTACT}")
set(CPACK_DEBIAN_PACKAGE_SECTION "science")
set(CPACK_DEBIAN_PACKAGE_PRIORITY "optional")
# The extended description (the summary above is its first line); CPack indents it.
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "teleop-master and teleop-slave are the two real-time node processes of a bilateral
teleoperator (1 kHz loops, haptic devices, a CURVE-secured ZeroMQ link); teleop-supervisor
analyses the running system with its measured round trip, guards parameter changes and
records sessions; teleopctl analyses configurations, simulates scenes and commands the nodes.
Includes systemd units (installed disabled) and example configurations in
/usr/share/teleop/examples.")
# Depends from the shared libraries the executables link (dpkg-shlibdeps, package dpkg-dev).
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# systemd-sysusers creates the user when present; useradd (passwd) otherwise.
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "systemd")
if(TELEOP_BUILD_PYTHON)
  # The module (python/) runs in Debian's python3 and returns numpy arrays.
  set(CPACK_DEBIAN_PACKAGE_SUGGESTS "python3, python3-numpy")
endif()
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    "${_teleop_deploy}/debian/postinst" "${_teleop_deploy}/debian/prerm"
    "${_teleop_deploy}/debian/postrm")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION TRUE)

# `package_source` (not used by scripts/package.sh): the sources without builds or sessions.
set(CPACK_SOURCE_GENERATOR "TGZ")
set(CPACK_SOURCE_IGNORE_FILES "/\\.git/" "/build[^/]*/" "/sessions/" "/node_modules/" "/out/")

include(CPack)
