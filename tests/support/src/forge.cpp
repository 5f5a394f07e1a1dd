#include "vts/test/forge.hpp"

#include <xxhash.h>

#include <stdexcept>

#include "vts/archive/pmtiles.hpp"
#include "vts/protocol/codec.hpp"

namespace vts::test {

namespace {

void put_le(std::vector<std::uint8_t>& out, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

}  // namespace

std::vector<std::uint8_t> flat_tile(std::uint32_t width, std::uint32_t height, std::uint8_t value) {
  const std::uint64_t body_size = std::uint64_t(width) * height * 4;
  if (body_size == 0 || body_size > 0xFFFFFFFFu)
    throw std::runtime_error("flat_tile: a body of " + std::to_string(body_size) + " bytes");
  // The zstd frame: magic, descriptor (single segment, 4-byte content size), content size, then
  // RLE blocks of at most 128 KiB (the block size limit), the last one flagged.
  std::vector<std::uint8_t> body = {0x28, 0xB5, 0x2F, 0xFD, 0xA0};
  put_le(body, body_size, 4);
  constexpr std::uint64_t kBlock = 128u * 1024u;
  for (std::uint64_t done = 0; done < body_size;) {
    const std::uint64_t n = std::min(kBlock, body_size - done);
    done += n;
    const std::uint64_t last = done == body_size ? 1 : 0;
    put_le(body, n << 3 | 1u << 1 | last, 3);  // block type 1: RLE
    body.push_back(value);
  }
  std::vector<std::uint8_t> p;
  put_le(p, TileHeader::kSkippableMagic, 4);
  put_le(p, TileHeader::kHeaderBytes, 4);
  p.push_back(TileHeader::kVersion);
  p.push_back(static_cast<std::uint8_t>(CodecId::lossless));
  p.push_back(static_cast<std::uint8_t>(Filter::none));
  p.push_back(static_cast<std::uint8_t>(PixelFormat::rgba8));
  put_le(p, width, 4);
  put_le(p, height, 4);
  put_le(p, body_size, 4);
  put_le(p, XXH3_64bits(body.data(), body.size()), 8);
  put_le(p, 0, 8);
  p.insert(p.end(), body.begin(), body.end());
  if (auto v = verify_tile(p); !v)
    throw std::runtime_error("flat_tile does not verify: " + v.error().to_string());
  return p;
}

void copy_archive_replacing(const std::filesystem::path& from, const std::filesystem::path& to,
                            const std::map<TileId, std::vector<std::uint8_t>>& replace) {
  auto reader = archive::Reader::open(from);
  if (!reader) throw std::runtime_error(from.string() + ": " + reader.error().to_string());
  const archive::Reader& r = **reader;
  archive::WriterOptions o;
  o.path = to;
  o.min_zoom = r.header().min_zoom;
  o.max_zoom = r.header().max_zoom;
  auto w = archive::Writer::create(o);
  if (!w) throw std::runtime_error(to.string() + ": " + w.error().to_string());
  std::map<TileId, std::vector<std::uint8_t>> tiles = replace;
  Status walk = r.for_each_entry([&](const archive::Entry& e) {
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      const TileId id = *archive::tile_id_to_zxy(e.tile_id + i);
      if (tiles.count(id)) continue;
      auto bytes = r.get_by_tile_id(e.tile_id + i);
      if (!bytes) throw std::runtime_error(from.string() + ": " + bytes.error().to_string());
      tiles.emplace(id, std::move(*bytes));
    }
    return true;
  });
  if (!walk) throw std::runtime_error(from.string() + ": " + walk.error().to_string());
  for (const auto& [id, payload] : tiles)
    if (Status s = (*w)->add_tile(id, payload); !s)
      throw std::runtime_error(to.string() + ": " + s.error().to_string());
  if (auto f = (*w)->finish(r.metadata_json()); !f)
    throw std::runtime_error(to.string() + ": " + f.error().to_string());
}

}  // namespace vts::test
