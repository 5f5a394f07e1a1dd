// Build options of a synthetic source of w x h texels at 6 levels: what the shard plan tests cut.
#pragma once

#include <cstdint>
#include <optional>

#include "vts/builder/builder.hpp"

namespace vts::test {

inline BuildOptions synthetic_options(std::uint64_t w, std::uint64_t h) {
  BuildOptions o;
  o.synthetic = SyntheticSpec{w, h, std::nullopt, 6};
  return o;
}

}  // namespace vts::test
