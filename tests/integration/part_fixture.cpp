// Parts of many tiny tiles, for tests of the merge at a scale no build here reaches quickly
// (merge_scale.sh): the first N tile ids of a pyramid with 8-byte payloads — half distinct, a
// quarter one of 1000 uniform values, a quarter equal to the tile before (runs) — cut into the
// sub-pyramids under every tile of a split level, plus the apex.
//
//   part_fixture parts DIR N SPLIT [LEAF]    writes DIR/apex.part, DIR/shard-*.part, DIR/tiles (N)
//   part_fixture single OUT N [LEAF]         the same tiles through archive::Writer
//   part_fixture merge DIR OUT [LEAF]        merge_parts() of DIR/*.part in a child process;
//                                            prints {"seconds":…, "max_rss_kib":…, "tiles":…}
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/archive/pmtiles_part.hpp"

namespace {

namespace fs = std::filesystem;
using namespace vts;

std::uint64_t mix(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// The payload of tile `id` (runs repeat the payload of the first tile of the run).
std::uint64_t payload_of(std::uint64_t id) {
  while (id > 0 && mix(id) % 4 == 3) --id;  // the same as the tile before
  const std::uint64_t h = mix(id);
  return h % 4 == 2 ? 1 + h % 1000 : h | 0x8000000000000000ULL;
}

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "part_fixture: %s\n", what.c_str());
  std::exit(1);
}

void check(const Status& s) {
  if (!s) die(s.error().message);
}

archive::WriterOptions writer_options(const fs::path& out, std::uint64_t n, std::size_t leaf) {
  archive::WriterOptions o;
  o.path = out;
  o.max_zoom = archive::tile_id_to_zxy(n - 1).value().z;
  o.leaf_entries = leaf;
  return o;
}

void add(archive::TileSink& sink, std::uint64_t id) {
  const std::uint64_t v = payload_of(id);
  std::uint8_t b[8];
  std::memcpy(b, &v, 8);
  check(sink.add_tile(archive::tile_id_to_zxy(id).value(), b));
}

void write_parts(const fs::path& dir, std::uint64_t n, int split) {
  fs::create_directories(dir);
  // The tile count, for the merge's header (it reads each part's index only once, in the merge).
  if (std::FILE* f = std::fopen((dir / "tiles").c_str(), "w")) {
    std::fprintf(f, "%llu\n", static_cast<unsigned long long>(n));
    std::fclose(f);
  } else {
    die("cannot write " + (dir / "tiles").string());
  }
  const auto finish = [](archive::PartWriter& w) {
    auto r = w.finish({}, "{}");
    if (!r) die(r.error().message);
  };
  const archive::TileIdRange apex_range{
      0, archive::subtree_tile_ids({0, 0, 0}, static_cast<std::uint8_t>(split)).first - 1};
  if (split > 0) {
    auto w = archive::PartWriter::create(dir / "apex.part").value();
    for (std::uint64_t id = 0; id <= apex_range.last && id < n; ++id) add(*w, id);
    finish(*w);
  }
  const std::uint32_t side = 1u << split;
  const int max_z = archive::tile_id_to_zxy(n - 1).value().z;
  for (std::uint32_t y = 0; y < side; ++y)
    for (std::uint32_t x = 0; x < side; ++x) {
      auto w = archive::PartWriter::create(
                   dir / ("shard-" + std::to_string(x) + "-" + std::to_string(y) + ".part"))
                   .value();
      for (int z = split; z <= max_z; ++z) {
        const auto r = archive::subtree_tile_ids({static_cast<std::uint8_t>(split), x, y},
                                                 static_cast<std::uint8_t>(z));
        for (std::uint64_t id = r.first; id <= r.last && id < n; ++id) add(*w, id);
      }
      finish(*w);
    }
}

int merge(const fs::path& dir, const fs::path& out, std::size_t leaf) {
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid < 0) die("fork failed");
  if (pid == 0) {
    archive::MergeOptions m;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().extension() == ".part") m.parts.push_back(e.path());
    unsigned long long tiles = 0;
    std::FILE* f = std::fopen((dir / "tiles").c_str(), "r");
    if (!f || std::fscanf(f, "%llu", &tiles) != 1) die("no tile count in " + dir.string());
    std::fclose(f);
    m.archive = writer_options(out, tiles, leaf);
    m.metadata_json = "{}";
    auto r = archive::merge_parts(m);
    if (!r) {
      std::fprintf(stderr, "part_fixture: %s\n", r.error().message.c_str());
      ::_exit(1);
    }
    ::_exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  struct rusage ru {};
  ::getrusage(RUSAGE_CHILDREN, &ru);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return 1;
  auto reader = archive::Reader::open(out).value();
  std::printf("{\"seconds\":%.3f,\"max_rss_kib\":%ld,\"tiles\":%llu,\"leaves\":%llu}\n", s,
              ru.ru_maxrss, static_cast<unsigned long long>(reader->header().addressed_tiles),
              static_cast<unsigned long long>(reader->leaf_directory_count().value()));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> a(argv + 1, argv + argc);
  const auto leaf = [&](std::size_t i) {
    return a.size() > i ? std::stoul(a[i]) : archive::kLeafEntries;
  };
  if (a.size() >= 4 && a[0] == "parts") {
    write_parts(a[1], std::stoull(a[2]), std::stoi(a[3]));
    return 0;
  }
  if (a.size() >= 3 && a[0] == "single") {
    const std::uint64_t n = std::stoull(a[2]);
    auto w = archive::Writer::create(writer_options(a[1], n, leaf(3))).value();
    for (std::uint64_t id = 0; id < n; ++id) add(*w, id);
    auto r = w->finish("{}");
    if (!r) die(r.error().message);
    return 0;
  }
  if (a.size() >= 3 && a[0] == "merge") return merge(a[1], a[2], leaf(3));
  std::fprintf(
      stderr,
      "usage: part_fixture parts DIR N SPLIT | single OUT N [LEAF] | merge DIR OUT [LEAF]\n");
  return 2;
}
