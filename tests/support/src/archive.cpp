#include "vts/test/archive.hpp"

#include <stdexcept>

namespace vts::test {

BuildOptions synthetic_options(const std::filesystem::path& output, std::uint64_t width,
                               std::uint64_t height, std::optional<TexelRect> region,
                               int region_level) {
  BuildOptions o;
  o.synthetic = SyntheticSpec{width, height, region, region_level};
  o.output = output;
  o.threads = 2;
  return o;
}

BuildReport build_archive(const BuildOptions& options) {
  if (options.output.has_parent_path())
    std::filesystem::create_directories(options.output.parent_path());
  auto r = build_synthetic_pyramid(options);
  if (!r)
    throw std::runtime_error("build " + options.output.string() + ": " + r.error().to_string());
  return std::move(*r);
}

OpenedArchive open_archive(const std::filesystem::path& path) {
  OpenedArchive a;
  a.path = path;
  auto reader = archive::Reader::open(path);
  if (!reader) throw std::runtime_error(path.string() + ": " + reader.error().to_string());
  a.reader = *reader;
  auto st = a.reader->for_each_entry([&](const archive::Entry& e) {
    for (std::uint32_t i = 0; i < e.run_length; ++i)
      a.tiles.push_back(*archive::tile_id_to_zxy(e.tile_id + i));
    return true;
  });
  if (!st.ok()) throw std::runtime_error(path.string() + ": " + st.error().to_string());
  return a;
}

std::vector<std::uint8_t> read_all(const archive::Reader& reader) {
  std::vector<std::uint8_t> bytes(reader.size());
  if (Status s = reader.read(0, bytes); !s) throw std::runtime_error(s.error().to_string());
  return bytes;
}

OpenedArchive build_and_open(const BuildOptions& options) {
  build_archive(options);
  return open_archive(options.output);
}

}  // namespace vts::test
