// vts warm: fill the disk cache with a tileset's tiles, pinned, for offline use. Parses the
// arguments, opens the source (or the cache's saved description of it, offline), runs
// client::warm_cache and prints the summary (terminal or --json).
#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "commands.hpp"
#include "image_target.hpp"
#include "progress.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/client/warm.hpp"

namespace vts::cli {

namespace {

using Clock = std::chrono::steady_clock;

struct WarmArgs {
  std::string url, cache_dir, levels, region, bbox, cache_size = "10G";
  unsigned concurrency = 32;
  unsigned max_errors = 100;
  bool json = false, quiet = false;
  ImageTargetArgs image;
};

std::string levels_text(int a, int b) {
  return a == b ? std::to_string(a) : std::to_string(a) + "-" + std::to_string(b);
}

// The source, or when the network is gone, a cache warmed from this URL before: it remembers the
// tileset, so warm checks what the cache holds (and fails naming the tiles it lacks).
Result<std::shared_ptr<client::TileSource>> open_warm_source(const WarmArgs& a, bool& offline) {
  client::SourceOptions so;
  so.fetcher.max_in_flight = a.concurrency;
  if (auto st = apply_image_target(a.image, so); !st) return st.error();
  auto opened = client::open_source(a.url, so);
  if (!opened && opened.error().code == ErrorCode::io) {
    if (auto saved = client::load_source_info(a.cache_dir, a.url)) {
      std::fprintf(stderr, "vts warm: %s: %s; checking the cache offline\n", a.url.c_str(),
                   opened.error().message.c_str());
      opened = client::offline_source(std::move(*saved));
      offline = true;
    }
  }
  if (!opened) return opened.error();
  return std::shared_ptr<client::TileSource>(std::move(*opened));
}

Status check_request(const WarmArgs& a, const client::SourceInfo& info,
                     const client::WarmOptions& o) {
  const Geometry& g = info.info.geometry;
  if (o.last_level > g.max_zoom())
    return make_error(
        ErrorCode::invalid_argument,
        "--levels " + a.levels + ": " + info.key + " has levels 0-" + std::to_string(g.max_zoom()));
  if (o.region && !a.region.empty() && (o.region->x1 > g.width() || o.region->y1 > g.height()))
    return make_error(ErrorCode::invalid_argument,
                      "--region " + a.region + " reaches beyond the image (" +
                          std::to_string(g.width()) + "x" + std::to_string(g.height()) +
                          " texels at level " + std::to_string(g.max_zoom()) + ")");
  return {};
}

// A bar on a terminal (at most ten redraws a second); elsewhere (a log file, CI) a plain line
// every few seconds.
class WarmProgressPrinter {
 public:
  explicit WarmProgressPrinter(bool show) : show_(show), bar_("warm", "tiles", show) {}
  void operator()(const client::WarmProgress& p) {
    if (!show_) return;
    const auto now = Clock::now();
    const double t = p.seconds;
    const std::string rate =
        human_bytes(t > 0 ? std::uint64_t(double(p.bytes_network) / t) : 0) + "/s";
    if (tty_) {
      if (now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      bar_.update(
          p.done, p.total,
          human_bytes(p.bytes_network) + "  " + rate + "  " + std::to_string(p.cached) + " cached");
      return;
    }
    if (now - last_line_ < std::chrono::seconds(5)) return;
    last_line_ = now;
    const double tps = t > 0 ? double(p.done) / t : 0.0;
    const std::string eta =
        tps > 0 && p.done < p.total ? human_duration(double(p.total - p.done) / tps) : "--";
    std::fprintf(stderr, "warm: %llu/%llu tiles (%.1f%%), %.0f tiles/s, %s, %llu cached, ETA %s\n",
                 (unsigned long long)p.done, (unsigned long long)p.total,
                 p.total ? 100.0 * double(p.done) / double(p.total) : 100.0, tps, rate.c_str(),
                 (unsigned long long)p.cached, eta.c_str());
  }
  void finish() { bar_.finish(); }

 private:
  bool show_;
  bool tty_ = ProgressBar::stderr_is_terminal();
  ProgressBar bar_;
  Clock::time_point last_draw_ = Clock::now(), last_line_ = last_draw_;
};

void print_text(const WarmArgs& a, const std::string& key, const client::WarmOptions& o,
                const client::WarmReport& r) {
  using ull = unsigned long long;
  const double tps = r.seconds > 0 ? double(r.done()) / r.seconds : 0.0;
  const double bps = r.seconds > 0 ? double(r.bytes_network) / r.seconds : 0.0;
  std::printf("warmed %s into %s: %llu/%llu tiles of levels %s in %s (%.0f tiles/s, %s/s)\n",
              key.c_str(), a.cache_dir.c_str(), ull(r.done()), ull(r.tiles_total),
              levels_text(o.first_level, o.last_level).c_str(), human_duration(r.seconds).c_str(),
              tps, human_bytes(std::uint64_t(bps)).c_str());
  std::printf("  from network    %llu (%s)\n", ull(r.network),
              human_bytes(r.bytes_network).c_str());
  std::printf("  already cached  %llu (%s)\n", ull(r.cached), human_bytes(r.bytes_cached).c_str());
  std::printf("  absent          %llu\n", ull(r.absent));
  std::printf("  failed          %llu\n", ull(r.failed));
  if (r.done() < r.tiles_total)
    std::printf("  not done        %llu (run again to resume)\n", ull(r.tiles_total - r.done()));
  const client::DiskCacheStats& ds = r.cache;
  std::printf("cache: %llu tiles, %s (%llu pinned, %s) of %s\n", ull(ds.tiles),
              human_bytes(ds.bytes).c_str(), ull(ds.pinned_tiles),
              human_bytes(ds.pinned_bytes).c_str(), human_bytes(ds.max_bytes).c_str());
}

// The exit code: 0 only when every tile is warmed.
int warm_exit(const WarmArgs& a, const client::WarmReport& r) {
  for (const auto& e : r.first_errors) std::fprintf(stderr, "vts: warm: %s\n", e.c_str());
  const std::string total = std::to_string(r.tiles_total);
  if (r.disk_error) return report_error(*r.disk_error);
  if (r.interrupted)
    return report_error(
        make_error(ErrorCode::cancelled, "interrupted: " + std::to_string(r.done()) + " of " +
                                             total + " tiles done; run again to resume"));
  if (r.failed > 0)
    return report_error(
        make_error(ErrorCode::io, std::to_string(r.failed) + " of " + total + " tiles failed" +
                                      (r.too_many_errors ? " (stopped after --max-errors " +
                                                               std::to_string(a.max_errors) + ")"
                                                         : std::string()) +
                                      "; run again to retry them"));
  if (!r.complete())
    return report_error(make_error(
        ErrorCode::internal,
        std::to_string(r.tiles_total - r.done()) + " of " + total + " tiles were not warmed"));
  return 0;
}

// Everything that can be checked without the network is checked first, and nothing touches the
// cache folder before the source has opened and the request fits its geometry.
Result<client::WarmOptions> warm_options(const WarmArgs& a) {
  client::WarmOptions o;
  if (!a.levels.empty()) {
    auto l = parse_level_range(a.levels, "--levels");
    if (!l) return l.error();
    o.first_level = l->first;
    o.last_level = l->second;
  }
  if (!a.region.empty()) {
    auto r = parse_texel_rect(a.region, "--region");
    if (!r) return r.error();
    o.region = *r;
  }
  if (!a.bbox.empty()) {
    auto b = parse_numbers(a.bbox, 4, "--bbox", "W,S,E,N");
    if (!b) return b.error();
    o.bbox = LonLatBounds{(*b)[0], (*b)[1], (*b)[2], (*b)[3]};
  }
  auto cache_size = parse_byte_size(a.cache_size, "--cache-size");
  if (!cache_size) return cache_size.error();
  if (a.cache_dir.empty()) return make_error(ErrorCode::invalid_argument, "--cache-dir is empty");
  o.cache_dir = a.cache_dir;
  o.cache_bytes = *cache_size;
  o.concurrency = a.concurrency;
  o.max_errors = a.max_errors;
  return o;
}

int run_warm(const WarmArgs& a) {
  auto opts = warm_options(a);
  if (!opts) return report_error(opts.error());
  client::WarmOptions& o = *opts;
  o.stop = &install_stop_signals();
  bool offline = false;
  auto source = open_warm_source(a, offline);
  if (!source) return report_error(source.error());
  o.source = *source;
  const client::SourceInfo& info = o.source->info();
  if (a.levels.empty()) o.last_level = info.info.geometry.max_zoom();
  if (o.bbox) {
    auto region = client::bbox_region(info.info, *o.bbox);
    if (!region)
      return report_error(
          make_error(region.error().code, info.key + ": " + region.error().message));
    if (region->empty())
      std::fprintf(stderr, "vts warm: --bbox %s does not overlap %s's footprint: nothing to warm\n",
                   a.bbox.c_str(), info.key.c_str());
    o.region = *region;
  }
  if (auto st = check_request(a, info, o); !st) return report_error(st.error());
  // Remember the tileset in the cache folder, so viewers and `vts cache serve` can open it with
  // the network gone.
  if (!offline) o.remember_as = a.url;
  WarmProgressPrinter printer(!a.quiet && !a.json);
  o.progress = [&printer](const client::WarmProgress& p) { printer(p); };
  auto report = client::warm_cache(o);
  printer.finish();
  if (!report) return report_error(report.error());
  if (a.json)
    std::printf("%s\n", client::warm_report_json(o, *report).dump(2).c_str());
  else if (!a.quiet)
    print_text(a, info.key, o, *report);
  std::fflush(stdout);
  return warm_exit(a, *report);
}

}  // namespace

Runner add_warm(CLI::App& app) {
  auto a = std::make_shared<WarmArgs>();
  CLI::App* c = app.add_subcommand(
      "warm", "Fill a disk cache with a tileset's tiles (pinned) for offline use; resumable");
  c->add_option("url", a->url,
                "Tileset: http://host:port/NAME (vts serve), a TileJSON URL, a {z}/{x}/{y} "
                "template, a remote .pmtiles URL or a local archive")
      ->required();
  c->add_option("--cache-dir", a->cache_dir, "Cache folder (created if missing)")->required();
  c->add_option("--levels", a->levels, "Levels A-B (or one level A); default all");
  c->add_option("--region", a->region,
                "Only tiles over x0,y0,x1,y1 (finest-level texels, half-open) at every level")
      ->excludes(c->add_option("--bbox", a->bbox,
                               "Georeferenced tilesets: only tiles over W,S,E,N (degrees), clipped "
                               "to the tileset's footprint, at every level"));
  c->add_option("--concurrency", a->concurrency, "Tile requests in flight")
      ->check(CLI::Range(1u, 1024u))
      ->capture_default_str();
  c->add_option("--cache-size", a->cache_size,
                "Cap on the cache's payload bytes, pinned included (suffix K/M/G/T: binary)")
      ->capture_default_str();
  c->add_option("--max-errors", a->max_errors, "Stop after this many failed tiles (0: never)")
      ->capture_default_str();
  add_image_target_options(c, a->image);
  c->add_flag("--json", a->json, "Print the summary as JSON on stdout");
  c->add_flag("-q,--quiet", a->quiet, "No progress or summary");
  return [a] { return run_warm(*a); };
}

}  // namespace vts::cli
