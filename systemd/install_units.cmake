# Install-time step of systemd/CMakeLists.txt: writes the units and the tmpfiles.d entry
# with the paths of this installation (CMAKE_INSTALL_PREFIX as given to
# `cmake --install --prefix`), then installs them (DESTDIR is honoured).

function(stereod_absolute out path)
  if(IS_ABSOLUTE "${path}")
    set(${out} "${path}" PARENT_SCOPE)
  else()
    set(${out} "${CMAKE_INSTALL_PREFIX}/${path}" PARENT_SCOPE)
  endif()
endfunction()

stereod_absolute(STEREOD_BIN_DIR "${STEREOD_BIN_DIR_REL}")
stereod_absolute(STEREOD_DOC_DIR "${STEREOD_DOC_DIR_REL}")
stereod_absolute(STEREOD_DATA_DIR "${STEREOD_DATA_DIR_REL}")
stereod_absolute(unit_dir "${STEREOD_SYSTEMD_UNIT_DIR}")
stereod_absolute(tmpfiles_dir "${STEREOD_TMPFILES_DIR}")

# Staged per installation: installs into different prefixes may run at once (tests).
string(MD5 stage "$ENV{DESTDIR}|${CMAKE_INSTALL_PREFIX}")
set(STEREOD_UNIT_BUILD_DIR "${STEREOD_UNIT_BUILD_DIR}/${stage}")

configure_file("${STEREOD_UNIT_SOURCE_DIR}/stereod.service.in"
               "${STEREOD_UNIT_BUILD_DIR}/stereod.service" @ONLY)
configure_file("${STEREOD_UNIT_SOURCE_DIR}/stereod.socket.in"
               "${STEREOD_UNIT_BUILD_DIR}/stereod.socket" @ONLY)
configure_file("${STEREOD_UNIT_SOURCE_DIR}/stereod.tmpfiles.conf.in"
               "${STEREOD_UNIT_BUILD_DIR}/tmpfiles/stereod.conf" @ONLY)

file(INSTALL DESTINATION "${unit_dir}" TYPE FILE
     FILES "${STEREOD_UNIT_BUILD_DIR}/stereod.service" "${STEREOD_UNIT_BUILD_DIR}/stereod.socket")
file(INSTALL DESTINATION "${tmpfiles_dir}" TYPE FILE
     FILES "${STEREOD_UNIT_BUILD_DIR}/tmpfiles/stereod.conf")
file(REMOVE_RECURSE "${STEREOD_UNIT_BUILD_DIR}")
