// vts build's inputs: the command line's paths, quoted glob patterns expanded here (for more files
// than a command line holds), and --input-list FILE. Built only with the builder.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "vts/base/result.hpp"

namespace vts::cli {

// The inputs in order: each argument (an argument with * ? or [ that is not an existing file is a
// glob(3) pattern, its matches sorted; one matching nothing is an error naming it), then the lines
// of `list_file` unless it is empty (one path per line as given, relative to the current
// directory; blank lines and lines starting with # skipped). The list is read with read_file:
// missing is not_found, a FIFO or a device invalid_argument, each naming --input-list and the file.
Result<std::vector<std::filesystem::path>> expand_inputs(const std::vector<std::string>& args,
                                                         const std::string& list_file);

}  // namespace vts::cli
