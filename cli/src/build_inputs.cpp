// vts build's inputs: globs and --input-list.
#include "build_inputs.hpp"

#include <glob.h>

#include <algorithm>
#include <string_view>
#include <system_error>

#include "vts/base/file_io.hpp"

namespace vts::cli {

namespace {

bool is_pattern(const std::string& arg) {
  if (arg.find_first_of("*?[") == std::string::npos) return false;
  std::error_code ec;
  return !std::filesystem::exists(arg, ec);  // a file whose name has such characters is a file
}

Status expand_glob(const std::string& pattern, std::vector<std::filesystem::path>& out) {
  glob_t g{};
  const int rc = glob(pattern.c_str(), GLOB_ERR, nullptr, &g);
  if (rc == 0) {
    std::vector<std::string> found(g.gl_pathv, g.gl_pathv + g.gl_pathc);
    std::sort(found.begin(), found.end());
    out.insert(out.end(), found.begin(), found.end());
  }
  globfree(&g);
  if (rc == GLOB_NOMATCH)
    return make_error(ErrorCode::not_found, "input pattern '" + pattern + "' matches no file");
  if (rc != 0)
    return make_error(ErrorCode::io, "input pattern '" + pattern + "': cannot read a directory");
  return {};
}

}  // namespace

Result<std::vector<std::filesystem::path>> expand_inputs(const std::vector<std::string>& args,
                                                         const std::string& list_file) {
  std::vector<std::filesystem::path> out;
  for (const std::string& arg : args) {
    if (!is_pattern(arg)) {
      out.emplace_back(arg);
    } else if (Status s = expand_glob(arg, out); !s) {
      return s.error();
    }
  }
  if (list_file.empty()) return out;
  // Through read_file: a FIFO or a device (/dev/zero) is refused before a byte is read.
  auto text = read_file(list_file);
  if (!text) {
    Error e = std::move(text).error();
    e.message = "--input-list '" + list_file + "' cannot be read: " + e.message;
    return e;
  }
  std::string_view rest = *text;
  while (!rest.empty()) {
    const std::size_t end = rest.find('\n');
    std::string_view line = rest.substr(0, end);
    rest.remove_prefix(end == std::string_view::npos ? rest.size() : end + 1);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.empty() || line.front() == '#') continue;
    out.emplace_back(line);
  }
  return out;
}

}  // namespace vts::cli
