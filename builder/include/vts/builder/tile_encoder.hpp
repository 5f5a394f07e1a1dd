// Encoding a tile of any codec: what the builder (and the accuracy tables, tests and benchmarks
// that make tiles) calls. `lossless` is protocol's encoder (vts::encode_lossless(), the inverse of
// its decoder); `bc1` searches each 4x4 block's endpoints here, with stb_dxt or libsquish, and
// frames the blocks with vts::pack_tile(). The encoders live in the builder, not in protocol,
// so the programs that only read tiles (server, client, renderer, load tester) never link them.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/codec.hpp"

namespace vts {
inline namespace builder {

// How hard the bc1 encoder searches for each 4x4 block's two endpoint colours. Every mode writes
// the same format; they differ in encode time and error (docs/ACCURACY.md, table 1):
//   fast: stb_dxt (stb_compress_dxt_block, STB_DXT_HIGHQUAL): the principal axis by power
//         iteration, endpoints refined twice by least squares;
//   high: libsquish cluster fit: searches the orderings of the 16 texels along the
//         principal axis;
//   best: libsquish iterative cluster fit: repeats the cluster fit with the refined axis.
enum class Bc1Quality : std::uint8_t { fast, high, best };

const char* bc1_quality_name(Bc1Quality q) noexcept;
// invalid_argument naming the known qualities unless `name` is one of them (exact, lower case).
Result<Bc1Quality> parse_bc1_quality(std::string_view name);

struct EncodeOptions {
  int zstd_level = 3;  // 1..19 (negative fast levels also accepted by zstd)
  FilterChoice filter = FilterChoice::automatic;  // lossless: automatic keeps the smaller of
                                                  // none / gradient; bc1 takes no filter
  Bc1Quality bc1 = Bc1Quality::fast;              // bc1 only (docs/ACCURACY.md: fast is 40x quicker
                                                  // than high for 0.3 dB less on the Earth)
};

// Encodes an rgba8 image (vts::check_encode_input(): 1..TileHeader::kMaxDimension texels a side,
// width * height * 4 bytes) into a complete payload of `codec`. bc1: texels with alpha < 128 become
// BC1's transparent black, the others opaque; partial blocks of a size that is not a multiple of 4
// repeat the edge texels. invalid_argument on a bad image, codec or zstd level. Thread-safe;
// the result's capacity is its size.
Result<std::vector<std::uint8_t>> encode_tile(const TileImage& image, CodecId codec,
                                              const EncodeOptions& options = {});

}  // namespace builder
}  // namespace vts
