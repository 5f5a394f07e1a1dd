// vts build's inputs: globs and --input-list.
#include "build_inputs.hpp"

#include <glob.h>

#include <algorithm>
#include <fstream>
#include <system_error>

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
  std::ifstream in(list_file);
  if (!in)
    return make_error(ErrorCode::not_found, "--input-list '" + list_file + "' cannot be read");
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line.front() == '#') continue;
    out.emplace_back(line);
  }
  if (in.bad()) return make_error(ErrorCode::io, "--input-list '" + list_file + "': read error");
  return out;
}

}  // namespace vts::cli
