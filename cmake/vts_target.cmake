# One place that configures every vtstream target the same way: language level, warnings and
# sanitizers. Call vts_configure_target(<target>) right after add_library/add_executable.
function(vts_configure_target target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wshadow -Wnon-virtual-dtor
                                           -Wno-missing-field-initializers)
  if(VTS_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(CMAKE_UNITY_BUILD AND CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    # In a unity source each .cpp is an included file, and GCC then warns about a class that
    # uses its own file's anonymous namespace (a Pimpl holding a file-local type, a test fixture):
    # harmless, and silent when the same file is compiled alone.
    target_compile_options(${target} PRIVATE -Wno-subobject-linkage)
  endif()
endfunction()

# vts_enable_sanitizers(<OFF|ON|address|thread>): applied globally (before any target) so that
# every library and test in the tree is instrumented the same way. address (or ON) is ASan +
# UBSan; thread is TSan (which cannot be combined with ASan). Sets VTS_SANITIZER to address,
# thread or "" (none).
macro(vts_enable_sanitizers kind)
  string(TOLOWER "${kind}" _vts_sanitize)
  set(VTS_SANITIZER "")
  if(_vts_sanitize STREQUAL "address" OR _vts_sanitize STREQUAL "on")
    add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer
                        -fno-sanitize-recover=undefined)
    add_link_options(-fsanitize=address,undefined)
    set(VTS_SANITIZER address)
  elseif(_vts_sanitize STREQUAL "thread")
    add_compile_options(-fsanitize=thread -fno-omit-frame-pointer)
    if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
      # GCC warns that TSan does not model std::atomic_thread_fence, once per Asio handler.
      add_compile_options(-Wno-tsan)
    endif()
    add_link_options(-fsanitize=thread)
    set(VTS_SANITIZER thread)
  elseif(NOT _vts_sanitize STREQUAL "off" AND NOT _vts_sanitize STREQUAL "")
    message(FATAL_ERROR "VTS_SANITIZE=${kind}: expected OFF, address, thread (or ON)")
  endif()
endmacro()

# vts_library(<name> [PUBLIC deps...] [PRIVATE deps...]): the library of the current folder,
# vts::<name>. Every library is laid out the same way: its sources are every src/*.cpp (globbed,
# so a file dropped into src/ is part of the library it sits in), its public headers live under
# include/vts/<name>/, and it is configured by vts_configure_target().
function(vts_library name)
  cmake_parse_arguments(ARG "" "" "PUBLIC;PRIVATE" ${ARGN})
  file(GLOB sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/*.cpp)
  add_library(vts_${name} ${sources})
  add_library(vts::${name} ALIAS vts_${name})
  vts_configure_target(vts_${name})
  target_include_directories(vts_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_link_libraries(vts_${name} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE})
  # The libraries parse untrusted bytes (archives, tiles, HTTP, JSON, images): an implicit
  # narrowing of a size or an offset is a warning, and with VTS_WERROR an error.
  # (Clang's -Wconversion also turns on -Wsign-conversion, which GCC's leaves off: kept off there
  # too, so both compilers hold the code to the same rule.)
  target_compile_options(vts_${name} PRIVATE -Wconversion
                                             $<$<CXX_COMPILER_ID:Clang>:-Wno-sign-conversion>)
endfunction()

# vts_install_executable(<target>): installs the executable into bin/ stripped, with its debug
# information kept apart in bin/.debug/<name>.debug and named by a .gnu_debuglink section, where
# gdb, perf and eu-stack look for it. A build without debug information (Release) installs the
# stripped executable and a small .debug file of symbols only.
function(vts_install_executable target)
  install(TARGETS ${target} RUNTIME DESTINATION bin)
  if(NOT CMAKE_OBJCOPY)
    message(FATAL_ERROR "vts_install_executable: no objcopy (binutils) found")
  endif()
  set(name "$<TARGET_FILE_NAME:${target}>")
  install(CODE "
    set(_bin \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/bin\")
    file(MAKE_DIRECTORY \"\${_bin}/.debug\")
    execute_process(COMMAND \"${CMAKE_OBJCOPY}\" --only-keep-debug \"\${_bin}/${name}\"
                            \"\${_bin}/.debug/${name}.debug\" COMMAND_ERROR_IS_FATAL ANY)
    execute_process(COMMAND \"${CMAKE_OBJCOPY}\" --strip-debug --strip-unneeded
                            \"--add-gnu-debuglink=\${_bin}/.debug/${name}.debug\" \"\${_bin}/${name}\"
                            COMMAND_ERROR_IS_FATAL ANY)
    message(STATUS \"Stripped: \${_bin}/${name} (debug information: \${_bin}/.debug/${name}.debug)\")
  ")
endfunction()
