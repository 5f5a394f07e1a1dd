# Cache daemon: `vts cache serve` in front of a real upstream (an in-process
# vts::HttpServer), driven by libcurl and raw sockets; and the server's AsyncTileProvider hook
# with a fake provider. Included by tests/integration/CMakeLists.txt, which provides GTest and
# PkgConfig::CURL.

add_executable(test_cache_daemon ${CMAKE_CURRENT_LIST_DIR}/test_cache_daemon.cpp)
vts_configure_target(test_cache_daemon)
target_link_libraries(test_cache_daemon PRIVATE vts::server vts::builder vts::client vts::protocol
                                                vts::test_support PkgConfig::CURL
                                                GTest::gtest_main Threads::Threads)
target_compile_definitions(test_cache_daemon PRIVATE VTS_EXECUTABLE="$<TARGET_FILE:vts>")
add_dependencies(test_cache_daemon vts)
# One ctest per gtest case: integration.daemon.<Suite>.<Case>. They start servers and daemons on
# loopback and stop the upstream under them, so they run alone.
gtest_discover_tests(test_cache_daemon
  TEST_PREFIX integration.daemon.
  DISCOVERY_TIMEOUT 60
  PROPERTIES LABELS integration RUN_SERIAL TRUE TIMEOUT 120)

# `vts cache serve` in front of a slow region of a real `vts serve` (slow_origin.py): abandoned
# fetches are cancelled down to libcurl, a slow region holds at most its cap, a deadline answers
# 503. It asserts sub-2 s answers, so it runs alone.
vts_integration_test(daemon.slow_origin_region_cannot_stall_other_misses cache_slow_origin.sh)
set_tests_properties(integration.daemon.slow_origin_region_cannot_stall_other_misses PROPERTIES
  RUN_SERIAL TRUE TIMEOUT 180)
