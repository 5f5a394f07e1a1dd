// store_probe: the store (vts::store) driven from shell tests against real servers (s3rver,
// nginx). Options come from the environment (StoreOptions::from_environment: AWS_* variables),
// with STORE_TIMEOUT_MS and STORE_RETRIES for the limits. Every failure prints
// "error CODE: MESSAGE" on stdout and exits with vts::exit_code(CODE).
//
//   store_probe compare LOCAL URL   every tile of URL equals LOCAL's; prints "open_requests N",
//                                   "tiles N", then "warm_tile_requests N" for one tile beyond
//                                   the first block read again (directories cached), then
//                                   "requests_total N"
//   store_probe hold URL            opens URL (prints "opened"), waits for a line on stdin, then
//                                   reads every tile: "read ok" or the error, and "elapsed_ms N"
//   store_probe etag URL            object_etag()
//   store_probe get URL MAX         get_object(): the bytes to stdout
//   store_probe list PREFIX         list_objects(): "URL SIZE ETAG" lines
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include "vts/archive/pmtiles.hpp"
#include "vts/store/store.hpp"

namespace {

using vts::ErrorCode;

int report(const vts::Error& e) {
  std::cout << "error " << vts::error_code_name(e.code) << ": " << e.message << std::endl;
  return vts::exit_code(e.code);
}

vts::store::StoreOptions options() {
  auto o = vts::store::StoreOptions::from_environment();
  if (!o) {
    report(o.error());
    std::exit(vts::exit_code(o.error().code));
  }
  if (const char* t = std::getenv("STORE_TIMEOUT_MS"))
    o->timeout = std::chrono::milliseconds(std::atol(t));
  if (const char* r = std::getenv("STORE_RETRIES")) o->retries = std::atoi(r);
  o->retry_backoff = std::chrono::milliseconds(20);
  return std::move(*o);
}

vts::Result<std::shared_ptr<vts::archive::Reader>> open_remote(const std::string& url,
                                                               const vts::store::StoreOptions& o) {
  auto source = vts::store::open_object(url, o);
  if (!source) return std::move(source).error();
  return vts::archive::Reader::open_source(std::move(*source));
}

// Every tile of `reader` (entries of `index`, a local copy) read; the first error, if any.
vts::Status read_every_tile(const vts::archive::Reader& reader, const vts::archive::Reader& index,
                            std::uint64_t* count) {
  vts::Status failed;
  vts::Status walk = index.for_each_entry([&](const vts::archive::Entry& e) {
    auto remote = reader.get_by_tile_id(e.tile_id);
    if (!remote) {
      failed = remote.error();
      return false;
    }
    if (count != nullptr) {
      auto local = index.get_by_tile_id(e.tile_id);
      if (!local || *local != *remote) {
        failed = vts::make_error(ErrorCode::corrupt,
                                 "tile id " + std::to_string(e.tile_id) + " differs");
        return false;
      }
      ++*count;
    }
    return true;
  });
  if (!failed) return failed;
  return walk;
}

int compare(const std::string& local_path, const std::string& url) {
  const auto o = options();
  auto local = vts::archive::Reader::open(local_path);
  if (!local) return report(local.error());
  auto remote = open_remote(url, o);
  if (!remote) return report(remote.error());
  std::cout << "open_requests " << o.counters->requests.load() << "\n";
  std::uint64_t tiles = 0;
  if (vts::Status s = read_every_tile(**remote, **local, &tiles); !s) return report(s.error());
  std::cout << "tiles " << tiles << "\n";
  // The last tile in the file lies beyond the first block: read again, it costs one GET.
  vts::archive::Entry last{};
  (void)(*local)->for_each_entry([&](const vts::archive::Entry& e) {
    if (e.offset >= last.offset) last = e;
    return true;
  });
  if ((*local)->header().tile_data_offset + last.offset < o.first_block) {
    return report(vts::make_error(ErrorCode::invalid_argument, "archive within the first block"));
  }
  const std::uint64_t before = o.counters->requests.load();
  auto tile = (*remote)->get_by_tile_id(last.tile_id);
  if (!tile) return report(tile.error());
  std::cout << "warm_tile_requests " << o.counters->requests.load() - before << "\n";
  std::cout << "requests_total " << o.counters->requests.load() << std::endl;
  return 0;
}

int hold(const std::string& url) {
  const auto o = options();
  auto remote = open_remote(url, o);
  if (!remote) return report(remote.error());
  std::cout << "opened" << std::endl;
  std::string line;
  std::getline(std::cin, line);
  const auto start = std::chrono::steady_clock::now();
  const vts::Status s = read_every_tile(**remote, **remote, nullptr);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                      std::chrono::steady_clock::now() - start)
                      .count();
  if (s) std::cout << "read ok" << std::endl;
  std::cout << "elapsed_ms " << ms << std::endl;
  return s ? 0 : report(s.error());
}

int run(int argc, char** argv) {
  const std::string cmd = argc > 1 ? argv[1] : "";
  if (cmd == "compare" && argc == 4) return compare(argv[2], argv[3]);
  if (cmd == "hold" && argc == 3) return hold(argv[2]);
  if (cmd == "etag" && argc == 3) {
    auto e = vts::store::object_etag(argv[2], options());
    if (!e) return report(e.error());
    std::cout << *e << std::endl;
    return 0;
  }
  if (cmd == "get" && argc == 4) {
    auto g = vts::store::get_object(argv[2], options(), std::stoull(argv[3]));
    if (!g) return report(g.error());
    std::cout << *g << std::flush;
    return 0;
  }
  if (cmd == "list" && argc == 3) {
    auto l = vts::store::list_objects(argv[2], options());
    if (!l) return report(l.error());
    for (const auto& i : *l) std::cout << i.url << " " << i.size << " " << i.etag << "\n";
    return 0;
  }
  std::cerr << "usage: store_probe compare LOCAL URL | hold URL | etag URL | get URL MAX | "
               "list PREFIX\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  return run(argc, argv);
}
