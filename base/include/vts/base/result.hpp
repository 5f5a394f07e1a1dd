// Errors as values. Expected failures (a corrupt tile, a truncated archive, a missing file) are
// returned as a Result carrying an ErrorCode and a human-readable message; exceptions are used only
// at the CLI edge. The numeric values of ErrorCode are stable: they map to process exit codes
// through one table, exit_code(), and to HTTP statuses through another, http_status().
#pragma once

#include <cassert>
#include <cstdint>
#include <string>
#include <utility>
#include <variant>

namespace vts {
inline namespace base {

enum class ErrorCode : std::uint8_t {
  ok = 0,
  invalid_argument = 1,  // the caller asked for something meaningless (bad option, bad tile id)
  not_found = 2,         // a tile, file or tileset that does not exist
  io = 3,                // the operating system refused (open, read, write, rename, full disk)
  corrupt = 4,           // bytes that do not follow the format: bad magic, bad offsets, cycles
  truncated = 5,         // the bytes end before the format says they should
  checksum = 6,          // bytes that parse but whose checksum does not match
  unsupported = 7,       // a well-formed feature we do not implement (unknown codec, version)
  too_large = 8,         // a declared size beyond our limits (decompression bombs, huge tiles)
  cancelled = 9,         // the operation was interrupted (SIGINT during a build)
  internal = 10,         // a bug: an invariant did not hold
  changed = 11,          // a file modified in place while it was being read; reopen and retry
  unavailable = 12,      // a remote store that timed out, dropped or answered 5xx; retry later
};

// Short stable name of an error code ("corrupt", "checksum", ...), for messages and --json.
const char* error_code_name(ErrorCode code) noexcept;
// Process exit code for an error: 0 for ok, 2 for invalid_argument, 3 for not_found, 4 for io,
// 5 for corrupt/truncated/checksum, 6 for unsupported/too_large, 75 for changed and unavailable
// (EX_TEMPFAIL: try again), 130 for cancelled, 70 internal.
int exit_code(ErrorCode code) noexcept;
// HTTP status for a request that failed with this code while a server read its own data: 200 for
// ok, 400 invalid_argument, 404 not_found, 503 cancelled, changed and unavailable (an archive being
// replaced, a store that is down: retry), and 500 for everything else (unreadable
// or damaged data on the server is never the client's fault).
int http_status(ErrorCode code) noexcept;

struct Error {
  ErrorCode code = ErrorCode::internal;
  std::string message;

  // "corrupt: leaf directory at offset 123 points past the end of the file"
  std::string to_string() const;
};

inline Error make_error(ErrorCode code, std::string message) {
  return Error{code, std::move(message)};
}

// A value or an Error. Accessing value() of an error (or error() of a value) is a bug and asserts.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const noexcept { return v_.index() == 0; }
  explicit operator bool() const noexcept { return ok(); }

  T& value() & {
    assert(ok());
    return std::get<0>(v_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<0>(v_);
  }
  T&& value() && {
    assert(ok());
    return std::get<0>(std::move(v_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const& {
    assert(!ok());
    return std::get<1>(v_);
  }
  Error&& error() && {
    assert(!ok());
    return std::get<1>(std::move(v_));
  }

 private:
  std::variant<T, Error> v_;
};

// Result of an operation that yields nothing but may fail.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT

  bool ok() const noexcept { return ok_; }
  explicit operator bool() const noexcept { return ok_; }
  const Error& error() const& {
    assert(!ok_);
    return error_;
  }

 private:
  Error error_{ErrorCode::ok, {}};
  bool ok_ = true;
};

}  // namespace base
}  // namespace vts
