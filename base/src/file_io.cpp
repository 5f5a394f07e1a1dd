#include "vts/base/file_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <random>

namespace vts {
inline namespace base {

namespace fs = std::filesystem;

namespace {

Error io_error(const std::string& what, const fs::path& path, int err) {
  return make_error(ErrorCode::io, what + " " + path.string() + ": " + std::strerror(err));
}

char lower(char c) noexcept {
  return c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c;
}

const char* file_kind(mode_t mode) noexcept {
  if (S_ISDIR(mode)) return "directory";
  if (S_ISCHR(mode)) return "character device";
  if (S_ISBLK(mode)) return "block device";
  if (S_ISFIFO(mode)) return "FIFO";
  if (S_ISSOCK(mode)) return "socket";
  return "special file";
}

bool is_space(char c) noexcept {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

}  // namespace

Status write_file_atomically(const fs::path& path,
                             const std::function<Status(int fd, const fs::path& temporary)>& write,
                             bool folder_sync_required) {
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  // A unique temporary name with O_EXCL (not mkstemp, which forces mode 0600).
  std::random_device rd;
  std::mt19937_64 rng((std::uint64_t{rd()} << 32) ^ rd() ^ static_cast<std::uint64_t>(::getpid()));
  fs::path tmp;
  int fd = -1;
  for (int attempt = 0; attempt < 100 && fd < 0; ++attempt) {
    char suffix[24];
    std::snprintf(suffix, sizeof suffix, "%08llx",
                  static_cast<unsigned long long>(rng() & 0xFFFFFFFFull));
    tmp = dir / ("." + path.filename().string() + ".tmp-" + suffix);
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) return io_error("cannot create", tmp, errno);
  }
  if (fd < 0) return io_error("cannot create a temporary file like", tmp, EEXIST);

  const auto discard = [&] {
    if (fd >= 0) ::close(fd);
    ::unlink(tmp.c_str());
  };
  auto fail = [&](const std::string& what, const fs::path& p, int err) -> Status {
    discard();
    return io_error(what, p, err);
  };
  if (Status st = write(fd, tmp); !st) {
    discard();
    return st;
  }
  if (::fsync(fd) != 0) return fail("cannot flush", tmp, errno);
  const int closed = ::close(fd);
  fd = -1;
  if (closed != 0) return fail("cannot write", tmp, errno);
  if (::rename(tmp.c_str(), path.c_str()) != 0) return fail("cannot rename a file to", path, errno);
  // Make the rename durable too. The file is complete either way.
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  const int synced = dfd >= 0 && ::fsync(dfd) == 0 ? 0 : errno;
  if (dfd >= 0) ::close(dfd);
  if (synced != 0 && folder_sync_required) return io_error("cannot fsync directory", dir, synced);
  return {};
}

Status write_file_atomically(const fs::path& path, std::string_view bytes) {
  return write_file_atomically(path, [bytes](int fd, const fs::path& tmp) -> Status {
    const char* data = bytes.data();
    std::size_t left = bytes.size();
    while (left > 0) {
      const ssize_t n = ::write(fd, data, left);
      if (n < 0) {
        if (errno == EINTR) continue;
        return io_error("cannot write", tmp, errno);
      }
      data += n;
      left -= static_cast<std::size_t>(n);
    }
    return {};
  });
}

Status check_output_is_not_an_input(const fs::path& output, std::span<const fs::path> inputs) {
  for (const fs::path& input : inputs) {
    std::error_code ec;
    // False (with ec set) when either does not exist: a new output cannot be an input.
    if (fs::equivalent(output, input, ec) && !ec) {
      return make_error(ErrorCode::invalid_argument,
                        "the output " + output.string() + " is the input " + input.string() +
                            " (the same file): writing it would destroy the input; choose "
                            "another output");
    }
  }
  return {};
}

Status check_output_file(const fs::path& output, std::string_view option,
                         std::initializer_list<fs::path> inputs) {
  if (output.empty()) return {};
  const fs::path dir = output.parent_path();
  std::error_code ec;
  if (fs::is_directory(output, ec) || !fs::is_directory(dir.empty() ? "." : dir, ec))
    return make_error(ErrorCode::invalid_argument, std::string(option) + " " + output.string() +
                                                       ": not a file in an existing folder");
  return check_output_is_not_an_input(output, {inputs.begin(), inputs.size()});
}

Result<int> open_input_file(const fs::path& path, struct stat* st_out) {
  const auto sys_error = [&](const char* what, int err) {
    return make_error(err == ENOENT ? ErrorCode::not_found : ErrorCode::io,
                      std::string(what) + " " + path.string() + ": " + std::strerror(err));
  };
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return sys_error("cannot open", errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    return sys_error("cannot stat", err);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return make_error(ErrorCode::invalid_argument,
                      "not a regular file: " + path.string() + " (" + file_kind(st.st_mode) + ")");
  }
  if (st_out != nullptr) *st_out = st;
  return fd;
}

Status check_input_file(const fs::path& path) {
  auto fd = open_input_file(path);
  if (!fd) return std::move(fd).error();
  ::close(*fd);
  return {};
}

Result<std::string> read_file(const fs::path& path) {
  struct stat st {};
  auto fd = open_input_file(path, &st);
  if (!fd) return std::move(fd).error();
  std::string text;
  text.reserve(static_cast<std::size_t>(st.st_size));
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(*fd, buf, sizeof buf);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(*fd);
      return io_error("cannot read", path, err);
    }
    text.append(buf, static_cast<std::size_t>(n));
  }
  ::close(*fd);
  return text;
}

std::string_view trim(std::string_view s) noexcept {
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

bool iequals(std::string_view a, std::string_view b) noexcept {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (lower(a[i]) != lower(b[i])) return false;
  return true;
}

bool istarts_with(std::string_view s, std::string_view prefix) noexcept {
  return s.size() >= prefix.size() && iequals(s.substr(0, prefix.size()), prefix);
}

bool icontains(std::string_view s, std::string_view part) noexcept {
  for (std::size_t i = 0; i + part.size() <= s.size(); ++i)
    if (iequals(s.substr(i, part.size()), part)) return true;
  return false;
}

std::string html_escape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out.push_back(c);
    }
  }
  return out;
}

std::string escape_controls(std::string_view s) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(s.size());
  const auto append_hex = [&out](unsigned char u) {
    out += "\\x";
    out += kHex[u >> 4];
    out += kHex[u & 15];
  };
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto u = static_cast<unsigned char>(s[i]);
    if (u < 0x20 || u == 0x7f) {
      append_hex(u);
    } else if (u == 0xc2 && i + 1 < s.size() && static_cast<unsigned char>(s[i + 1]) >= 0x80 &&
               static_cast<unsigned char>(s[i + 1]) <= 0x9f) {
      append_hex(u);  // U+0080..U+009F: a C1 control
      append_hex(static_cast<unsigned char>(s[++i]));
    } else {
      out += s[i];
    }
  }
  return out;
}

}  // namespace base
}  // namespace vts
