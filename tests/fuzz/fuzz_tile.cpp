// Fuzz target for tile payloads: the header parser, the checksum gate and the full decoder must
// return an Error for any bytes, never crash, hang or read out of bounds. Random bytes almost never
// pass the checksum, so the input is also fed to the body decoder behind the gate
// (decode_lossless_body) with the header it declares, or a header derived from it, so that
// hostile zstd frames reach the decompressor and the unfilter.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "codec_internal.hpp"  // the codec's private entry points (protocol/src)
#include "vts/protocol/codec.hpp"

namespace {

void check(bool ok) {
  if (!ok) std::abort();  // an invariant broke: let the fuzzer record the input
}

// Whatever texels a hostile body decodes to must survive our own encoder and decoder exactly.
void check_round_trip(const vts::TileImage& image, vts::Filter filter) {
  using namespace vts;
  const FilterChoice choice =
      filter == Filter::gradient ? FilterChoice::gradient : FilterChoice::none;
  auto payload = encode_lossless(image, LosslessOptions{1, choice});
  check(payload.ok());
  auto again = decode_tile(*payload);
  check(again.ok() && again->pixels == image.pixels);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace vts;
  const std::span<const std::uint8_t> payload(data, size);

  auto header = parse_tile_header(payload);
  auto verified = verify_tile(payload);
  auto decoded = decode_tile(payload);
  // Each stage only accepts what the previous one accepted.
  if (verified.ok()) check(header.ok());
  if (decoded.ok()) {
    check(verified.ok());
    check(decoded->width == header->width && decoded->height == header->height);
    check(decoded->pixels.size() == header->body_size);
  }

  if (size < TileHeader::kFrameBytes) return 0;
  const auto body = payload.subspan(TileHeader::kFrameBytes);
  if (header.ok() && header->codec == CodecId::lossless) {
    // The header is well formed: decode the body as if the checksum had matched.
    auto r = detail::decode_lossless_body(*header, body);
    if (r.ok()) {
      check(r->pixels.size() == header->body_size);
      check_round_trip(*r, header->filter);
    }
  } else {
    // Derive a small, valid header from the first bytes so a hostile body still gets decoded:
    // byte 8 picks the filter, bytes 12/16 the dimensions (1..64, so sizes stay fuzzable).
    TileHeader h;
    h.filter = (data[8] & 1) ? Filter::gradient : Filter::none;
    h.width = 1 + data[12] % 64;
    h.height = 1 + data[16] % 64;
    h.body_size = h.width * h.height * 4;
    auto r = detail::decode_lossless_body(h, body);
    if (r.ok()) {
      check(r->pixels.size() == h.body_size);
      check_round_trip(*r, h.filter);
    }
  }
  return 0;
}
