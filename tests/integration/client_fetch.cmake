# Client fetcher: the libcurl fetcher against FaultServer, an in-process upstream that
# injects faults chosen by URL (drop, reset, stall, slow, truncate, corrupt, 5xx, Retry-After).
# Included by tests/integration/CMakeLists.txt, which provides GTest and PkgConfig::CURL.

# The fault-injecting upstream: a library for gtest, and `fault_server ARCHIVE NAME [--port N]`
# for shell tests.
add_library(fault_server_lib STATIC ${CMAKE_CURRENT_LIST_DIR}/fault_server.cpp)
vts_configure_target(fault_server_lib)
target_include_directories(fault_server_lib PUBLIC ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(fault_server_lib PUBLIC vts::archive
                                       PRIVATE PkgConfig::XXHASH nlohmann_json::nlohmann_json
                                               Threads::Threads)

add_executable(fault_server ${CMAKE_CURRENT_LIST_DIR}/fault_server_main.cpp)
vts_configure_target(fault_server)
target_link_libraries(fault_server PRIVATE fault_server_lib Threads::Threads)

add_executable(test_fetcher ${CMAKE_CURRENT_LIST_DIR}/test_fetcher.cpp)
vts_configure_target(test_fetcher)
target_link_libraries(test_fetcher PRIVATE vts::client vts::protocol vts::test_support
                                           fault_server_lib GTest::gtest_main Threads::Threads)
# One ctest per gtest case: integration.fetch.<Suite>.<Case>. Several measure delays (backoff,
# Retry-After, prompt cancellation), so they run alone.
gtest_discover_tests(test_fetcher
  TEST_PREFIX integration.fetch.
  DISCOVERY_TIMEOUT 60
  PROPERTIES LABELS integration RUN_SERIAL TRUE TIMEOUT 120)
