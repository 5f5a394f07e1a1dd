#include "vts/base/result.hpp"

namespace vts {
inline namespace base {

const char* error_code_name(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::ok:
      return "ok";
    case ErrorCode::invalid_argument:
      return "invalid_argument";
    case ErrorCode::not_found:
      return "not_found";
    case ErrorCode::io:
      return "io";
    case ErrorCode::corrupt:
      return "corrupt";
    case ErrorCode::truncated:
      return "truncated";
    case ErrorCode::checksum:
      return "checksum";
    case ErrorCode::unsupported:
      return "unsupported";
    case ErrorCode::too_large:
      return "too_large";
    case ErrorCode::cancelled:
      return "cancelled";
    case ErrorCode::internal:
      return "internal";
    case ErrorCode::changed:
      return "changed";
    case ErrorCode::unavailable:
      return "unavailable";
  }
  return "unknown";
}

int exit_code(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::ok:
      return 0;
    case ErrorCode::invalid_argument:
      return 2;
    case ErrorCode::not_found:
      return 3;
    case ErrorCode::io:
      return 4;
    case ErrorCode::corrupt:
    case ErrorCode::truncated:
    case ErrorCode::checksum:
      return 5;
    case ErrorCode::unsupported:
    case ErrorCode::too_large:
      return 6;
    case ErrorCode::changed:
    case ErrorCode::unavailable:
      return 75;
    case ErrorCode::cancelled:
      return 130;
    case ErrorCode::internal:
      return 70;
  }
  return 70;
}

int http_status(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::ok:
      return 200;
    case ErrorCode::invalid_argument:
      return 400;
    case ErrorCode::not_found:
      return 404;
    case ErrorCode::cancelled:
    case ErrorCode::changed:
    case ErrorCode::unavailable:
      return 503;
    case ErrorCode::io:
    case ErrorCode::corrupt:
    case ErrorCode::truncated:
    case ErrorCode::checksum:
    case ErrorCode::unsupported:
    case ErrorCode::too_large:
    case ErrorCode::internal:
      return 500;
  }
  return 500;
}

std::string Error::to_string() const {
  return std::string(error_code_name(code)) + ": " + message;
}

}  // namespace base
}  // namespace vts
