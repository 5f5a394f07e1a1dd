// Deeply nested JSON documents, the shape of a hostile input that exhausts a recursive parser.
#pragma once

#include <cstddef>
#include <string>

namespace vts::test {

// `levels` arrays nested in one another, the innermost holding `inner`.
inline std::string nested_arrays(int levels, const std::string& inner = "") {
  return std::string(std::size_t(levels), '[') + inner + std::string(std::size_t(levels), ']');
}

// `levels` objects nested under the key "k", the innermost holding 1.
inline std::string nested_objects(int levels) {
  std::string s;
  for (int i = 0; i < levels; ++i) s += "{\"k\":";
  s += "1";
  for (int i = 0; i < levels; ++i) s += "}";
  return s;
}

}  // namespace vts::test
