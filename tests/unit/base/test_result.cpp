// The one table that maps error codes to names, exit statuses and HTTP statuses
// (docs/ARCHITECTURE.md "Errors" lists the exit statuses).
#include "vts/base/result.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>

namespace {

using vts::ErrorCode;

TEST(ErrorTable, EveryCodeHasItsOwnNameExitStatusAndHttpStatus) {
  struct Row {
    ErrorCode code;
    const char* name;
    int exit, http;
  };
  const Row rows[] = {
      {ErrorCode::ok, "ok", 0, 200},
      {ErrorCode::invalid_argument, "invalid_argument", 2, 400},
      {ErrorCode::not_found, "not_found", 3, 404},
      {ErrorCode::io, "io", 4, 500},
      {ErrorCode::corrupt, "corrupt", 5, 500},
      {ErrorCode::truncated, "truncated", 5, 500},
      {ErrorCode::checksum, "checksum", 5, 500},
      {ErrorCode::unsupported, "unsupported", 6, 500},
      {ErrorCode::too_large, "too_large", 6, 500},
      {ErrorCode::cancelled, "cancelled", 130, 503},
      {ErrorCode::internal, "internal", 70, 500},
      {ErrorCode::changed, "changed", 75, 503},
      {ErrorCode::unavailable, "unavailable", 75, 503},
  };
  std::set<std::string> names;
  for (const Row& r : rows) {
    SCOPED_TRACE(r.name);
    EXPECT_STREQ(vts::error_code_name(r.code), r.name);
    EXPECT_EQ(vts::exit_code(r.code), r.exit);
    EXPECT_EQ(vts::http_status(r.code), r.http);
    EXPECT_TRUE(names.insert(r.name).second);
  }
  EXPECT_EQ(vts::make_error(ErrorCode::changed, "a.pmtiles was modified").to_string(),
            "changed: a.pmtiles was modified");
}

}  // namespace
