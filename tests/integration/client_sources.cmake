# Tile sources: the local-archive, TileJSON and remote-archive sources over loopback,
# against the real `vts serve` (HttpServer in process) and FaultServer as a plain static file
# server with Range. Included by tests/integration/CMakeLists.txt after client_fetch.cmake, which
# defines fault_server_lib.
add_executable(test_sources ${CMAKE_CURRENT_LIST_DIR}/test_sources.cpp)
vts_configure_target(test_sources)
target_link_libraries(test_sources PRIVATE vts::client vts::server vts::builder vts::protocol
                                           vts::test_support fault_server_lib GTest::gtest_main
                                           Threads::Threads)
# One ctest per gtest case: integration.sources.<Suite>.<Case>.
gtest_discover_tests(test_sources
  TEST_PREFIX integration.sources.
  DISCOVERY_TIMEOUT 60
  PROPERTIES LABELS integration TIMEOUT 120)
