# Client caches: the SQLite disk cache under kill -9, a full disk and two processes at
# once, driven by `cache_torture` (fill / check) and checked with the real sqlite3 CLI.
# Included by tests/integration/CMakeLists.txt (VTS_INTEGRATION_ENV, BASH_EXECUTABLE come from it).

add_executable(cache_torture ${CMAKE_CURRENT_LIST_DIR}/cache_torture.cpp)
vts_configure_target(cache_torture)
target_link_libraries(cache_torture PRIVATE vts::client vts::protocol PkgConfig::SQLITE3
                                            PkgConfig::XXHASH)

find_program(VTS_SQLITE3_CLI sqlite3)
if(NOT VTS_SQLITE3_CLI)
  message(WARNING "tests/integration: the sqlite3 CLI was not found; run scripts/setup.sh")
  set(VTS_SQLITE3_CLI sqlite3)
endif()

set(VTS_CACHE_TEST_ENV ${VTS_INTEGRATION_ENV}
    "CACHE_TORTURE=$<TARGET_FILE:cache_torture>"
    "SQLITE3=${VTS_SQLITE3_CLI}")

# vts_cache_test(NAME SCRIPT): integration.cache.NAME runs SCRIPT with the environment above.
function(vts_cache_test name script)
  add_test(NAME integration.cache.${name}
           COMMAND ${BASH_EXECUTABLE} ${CMAKE_CURRENT_LIST_DIR}/${script})
  set_tests_properties(integration.cache.${name} PROPERTIES
    LABELS integration
    ENVIRONMENT "${VTS_CACHE_TEST_ENV}"
    TIMEOUT 300)
endfunction()

vts_cache_test(survives_kill_9_at_any_moment cache_crash.sh)
vts_cache_test(two_processes_share_one_folder cache_two_processes.sh)
# Needs to mount a 2 MiB tmpfs (root); exits 77 (shown as skipped) where mounting is not allowed.
vts_cache_test(full_disk_fails_cleanly_and_keeps_the_cache_valid cache_full_disk.sh)
set_tests_properties(integration.cache.full_disk_fails_cleanly_and_keeps_the_cache_valid
                     PROPERTIES SKIP_RETURN_CODE 77)
