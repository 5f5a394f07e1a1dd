# vts warm: the real `vts serve` on 127.0.0.1 port 0 warmed into a disk cache, which the
# sqlite3 CLI then checks; kill -9 and SIGINT mid-warm. Included by tests/integration/CMakeLists.txt
# (vts_integration_test comes from it).

find_program(VTS_SQLITE3_CLI sqlite3)
if(NOT VTS_SQLITE3_CLI)
  message(WARNING "tests/integration: the sqlite3 CLI was not found; run scripts/setup.sh")
  set(VTS_SQLITE3_CLI sqlite3)
endif()

# vts_warm_test(NAME PART): integration.warm.NAME runs `warm.sh PART`.
function(vts_warm_test name part)
  vts_integration_test(warm.${name} warm.sh ${part})
  set_property(TEST integration.warm.${name} APPEND PROPERTY ENVIRONMENT
               "SQLITE3=${VTS_SQLITE3_CLI}")
  set_tests_properties(integration.warm.${name} PROPERTIES TIMEOUT 120)
endfunction()

vts_warm_test(fills_the_cache_pinned_and_a_rerun_serves_it_from_disk fill)
vts_warm_test(levels_and_region_select_exactly_the_geometry_s_tiles subset)
vts_warm_test(kill_9_and_sigint_leave_a_valid_cache_that_resumes crash)
vts_warm_test(bad_input_fails_cleanly_and_creates_no_cache bad_input)
vts_warm_test(bbox_warms_exactly_the_footprint_tiles_of_the_box bbox)

# A host that ignores Range (python3 -m http.server): one download of the whole archive, or a
# clean failure over --max-download.
vts_integration_test(warm.host_ignoring_range_is_downloaded_once_or_refused warm_no_range.sh)
set_property(TEST integration.warm.host_ignoring_range_is_downloaded_once_or_refused APPEND
             PROPERTY ENVIRONMENT "SQLITE3=${VTS_SQLITE3_CLI}")
