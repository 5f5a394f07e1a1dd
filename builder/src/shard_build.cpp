// One shard of a plan, its apex, and the merge of their parts (vts/builder/shard.hpp).
#include <algorithm>
#include <chrono>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>

#include "build_core.hpp"
#include "cascade.hpp"
#include "input_drivers.hpp"
#include "shard_geo.hpp"
#include "shard_internal.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace builder {

namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

std::string tile_text(TileId t) {
  return std::to_string(t.z) + "/" + std::to_string(t.x) + "/" + std::to_string(t.y);
}

json manifest(const ShardPlan& plan, std::optional<std::size_t> index, std::optional<TileId> root,
              std::uint64_t tiles, std::uint64_t content_sum) {
  json j;
  j["plan_hash"] = plan.hash;
  j["part"] = index ? "shard" : "apex";
  if (index) j["shard"] = *index;
  if (root) j["root"] = tile_text(*root);
  j["tiles"] = tiles;
  j["content_sum"] = detail::content_hash_text(content_sum);
  detail::describe_part_build(plan, index, j);
  return j;
}

// A part about to be read: a regular file (a FIFO named like one would block the read forever).
Status check_part_file(const std::filesystem::path& path) {
  Status st = check_input_file(path);
  if (st || st.error().code != ErrorCode::not_found) return st;
  return make_error(ErrorCode::not_found, "missing part " + path.string());
}

// The part's manifest, checked against the plan (its build, the inputs it read): its content sum.
Result<std::uint64_t> check_manifest(const ShardPlan& plan, const archive::PartInfo& info) {
  auto parsed = parse_json(info.manifest_json, "part " + info.path.string() + "'s manifest");
  if (!parsed) return std::move(parsed).error();
  try {
    const json& j = *parsed;
    if (Status st = detail::check_part_build(plan, j, info.path); !st) return st.error();
    return std::stoull(j.at("content_sum").get<std::string>(), nullptr, 16);
  } catch (const std::exception& e) {
    return make_error(ErrorCode::corrupt,
                      "part " + info.path.string() + " has no valid manifest: " + e.what());
  }
}

Result<archive::PartInfo> open_part(const ShardPlan& plan, const std::filesystem::path& path,
                                    std::uint64_t* content_sum) {
  if (Status st = check_part_file(path); !st) return st.error();
  auto info = archive::read_part_info(path);
  if (!info)
    return make_error(info.error().code, "part " + path.string() + ": " + info.error().message);
  auto sum = check_manifest(plan, *info);
  if (!sum) return sum.error();
  if (content_sum) *content_sum = *sum;
  return info;
}

// The options a shard or the apex builds with: the plan's, with the caller's threads and callbacks.
BuildOptions run_options(const ShardPlan& plan, const ShardBuildOptions& so) {
  BuildOptions o = plan.options;
  o.threads = so.threads;
  o.on_progress = so.on_progress;
  o.cancel = so.cancel;
  return o;
}

// The inputs a shard opens (`chosen`) are the plan's.
Status check_inputs(const ShardPlan& plan, const std::vector<std::size_t>& chosen) {
  for (std::size_t i : chosen) {
    const PlanInput& in = plan.inputs[i];
    auto fp = input_fingerprint(in.path);
    if (!fp) return fp.error();
    std::error_code ec;
    const std::uint64_t size = std::filesystem::file_size(in.path, ec);
    if (size != in.size || *fp != in.fingerprint)
      return make_error(ErrorCode::invalid_argument,
                        "input " + in.path.string() +
                            " changed since the plan was made (size or fingerprint differs)");
  }
  return {};
}

// Runs `run` into a new part at `path` and finishes it.
// `extend` adds to the manifest once the tiles are built.
Result<ShardReport> write_part(const ShardPlan& plan, detail::BuildRun& run,
                               const std::filesystem::path& path, std::optional<std::size_t> index,
                               std::optional<TileId> root,
                               const std::function<Status(json&)>& extend = {}) {
  const auto t0 = Clock::now();
  // Not over a file the part is made from: an input, or (the apex) a shard's part.
  std::vector<std::filesystem::path> read = plan.options.inputs;
  for (std::size_t i = 0; i < plan.shards.size() && !index; ++i)
    read.push_back(path.parent_path() / shard_part_name(i));
  if (Status st = check_output_is_not_an_input(path, read); !st) return st.error();
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  auto part = archive::PartWriter::create(path);
  if (!part) return std::move(part).error();
  run.sink = part->get();
  auto result = detail::run_build(run);
  if (!result) {
    (*part)->abort();
    return std::move(result).error();
  }
  json m = manifest(plan, index, root, result->tiles, result->content_sum);
  if (extend)
    if (Status st = extend(m); !st) {
      (*part)->abort();
      return st.error();
    }
  std::vector<std::uint8_t> attachment;
  if (index && !plan.options.synthetic) {
    std::vector<ApexTile> kept;
    for (auto& [yx, payload] : result->kept) kept.push_back({yx.second, yx.first, payload});
    attachment = encode_apex_tiles(kept);
  }
  auto stats = (*part)->finish(attachment, m.dump());
  if (!stats) return std::move(stats).error();
  ShardReport r;
  r.part = path;
  r.root = root;
  r.tiles = result->tiles;
  r.content_sum = result->content_sum;
  r.stats = *stats;
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

}  // namespace

Result<ShardReport> build_shard(const ShardPlan& plan, std::size_t index,
                                const ShardBuildOptions& so) {
  detail::use_image_inputs();
  if (index >= plan.shards.size())
    return make_error(ErrorCode::invalid_argument,
                      "shard " + std::to_string(index) + " is out of range: the plan has " +
                          std::to_string(plan.shards.size()) + " shards (0.." +
                          std::to_string(plan.shards.size() - 1) + ")");
  const BuildOptions o = run_options(plan, so);
  auto geometry = detail::plan_geometry(plan);
  if (!geometry) return std::move(geometry).error();
  const TileId root = plan.shards[index];
  const Geometry& pg = *geometry;
  // The core: the finest texels under the root; the window adds the halo (shard_window), within
  // what the whole build reads (the footprint of georeferenced inputs).
  auto sw = shard_window(plan, index);
  if (!sw) return std::move(sw).error();
  const TexelRect core = sw->core, window = sw->window;
  const std::vector<std::size_t> chosen = detail::plan_inputs_meeting(plan, pg, window);
  if (Status st = check_inputs(plan, chosen); !st) return st.error();
  auto prepared = detail::prepare_shard_build(plan, o, chosen);
  if (!prepared) return std::move(prepared).error();
  const Geometry& g = *prepared->geometry;
  if (g.width() != plan.width || g.height() != plan.height || g.max_zoom() != plan.max_zoom)
    return make_error(ErrorCode::invalid_argument, "the inputs' geometry is not the plan's");
  std::vector<TileRect> emit = detail::build_emit_rects(*prepared);
  // Levels >= A of the sub-pyramid under the root; levels L .. A - 1 are the apex's.
  const int A = plan.apex_level;
  for (int z = 0; z <= g.max_zoom(); ++z) {
    TileRect& e = emit[static_cast<std::size_t>(z)];
    e = z < A ? TileRect{} : detail::shard_rect(e, root, z);
  }
  detail::BuildRun run;
  run.options = &o;
  run.scratch_dir = so.out_dir;
  run.geometry = &g;
  run.codec = prepared->codec;
  run.threads = so.threads;
  std::optional<detail::BuildPlan> bp;
  std::uint64_t texels_read = 0, core_texels = 0;
  if (prepared->synthetic) {
    run.synthetic = emit;  // generated directly: nothing read
  } else {
    auto p =
        detail::make_build_plan(g, o.downsample, window, emit, detail::plan_max_width(plan), A);
    if (!p) return std::move(p).error();
    bp = std::move(p).value();
    run.plan = &*bp;
    run.readers = detail::source_readers(*prepared, detail::worker_count(so.threads));
    run.keep = detail::BuildRun::Keep{A, emit[static_cast<std::size_t>(A)]};
    texels_read = window.width() * window.height();
    core_texels = core.width() * core.height();
  }
  auto r = write_part(plan, run, so.out_dir / shard_part_name(index), index, root);
  if (!r) return r;
  r->texels_read = texels_read;
  r->core_texels = core_texels;
  r->inputs_opened = chosen.size();
  return r;
}

namespace {

// Rows of the apex level A, assembled from the shards' lossless level-A tiles (their parts'
// attachments, encode_apex_tiles): the attachments of one row of shards held at a time, one tile
// row of them decoded at a time.
class ApexLevelRows {
 public:
  ApexLevelRows(const ShardPlan& plan, const Geometry& g, std::filesystem::path dir)
      : plan_(plan), g_(g), dir_(std::move(dir)), k_(plan.apex_level - plan.split_level) {
    hashes_.assign(plan.shards.size(), 0);
    hashed_.assign(plan.shards.size(), false);
  }
  // The attachment hash of each shard's part (index: shard), all of them read.
  Result<std::vector<std::uint64_t>> hashes() {
    for (std::size_t i = 0; i < plan_.shards.size(); ++i)
      if (!hashed_[i]) {
        auto info = open_part(plan_, dir_ / shard_part_name(i), nullptr);
        if (!info) return info.error();
        hashes_[i] = detail::attachment_hash(info->attachment);
        hashed_[i] = true;
      }
    return hashes_;
  }
  Status read(std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t n,
              std::uint8_t* out) {
    const std::uint64_t T = g_.tile_size(), B = g_.border(), S = g_.stored_size();
    std::memset(out, 0, (x1 - x0) * n * 4);
    for (std::uint32_t r = 0; r < n; ++r) {
      const std::uint64_t yy = y + r;
      if (Status st = load_row(static_cast<std::uint32_t>(yy / T)); !st) return st;
      for (std::uint64_t x = x0; x < x1;) {
        const auto tx = static_cast<std::uint32_t>(x / T);
        const std::uint64_t end = std::min(x1, (tx + 1) * T);
        auto it = tiles_.find(tx);
        if (it != tiles_.end()) {
          const std::uint8_t* src =
              it->second.pixels.data() + ((yy % T + B) * S + (x - tx * T + B)) * 4;
          std::memcpy(out + (std::size_t{r} * (x1 - x0) + (x - x0)) * 4, src, (end - x) * 4);
        }
        x = end;
      }
    }
    return {};
  }

 private:
  // The level-A tiles of the shards of row `sy` (level L), their payloads by (x, y).
  Status load_shards(std::uint32_t sy) {
    if (sy == shard_row_) return {};
    payloads_.clear();
    shard_row_ = sy;
    for (std::size_t i = 0; i < plan_.shards.size(); ++i) {
      const TileId root = plan_.shards[i];
      if (root.y != sy) continue;
      auto info = open_part(plan_, dir_ / shard_part_name(i), nullptr);
      if (!info) return info.error();
      hashes_[i] = detail::attachment_hash(info->attachment);
      hashed_[i] = true;
      auto tiles = decode_apex_tiles(info->attachment);
      if (!tiles)
        return make_error(ErrorCode::corrupt,
                          "part " + info->path.string() + ": " + tiles.error().message);
      for (ApexTile& t : *tiles) {
        if (t.x >> k_ != root.x || t.y >> k_ != root.y)
          return make_error(ErrorCode::corrupt, "part " + info->path.string() + " has a level-" +
                                                    std::to_string(plan_.apex_level) + " tile " +
                                                    std::to_string(t.x) + "/" +
                                                    std::to_string(t.y) + " outside its shard");
        payloads_[{t.x, t.y}] = {i, std::move(t.payload)};
      }
    }
    return {};
  }
  Status load_row(std::uint32_t ty) {
    if (ty == row_) return {};
    tiles_.clear();
    row_ = ty;
    if (Status st = load_shards(ty >> k_); !st) return st;
    for (auto& [xy, entry] : payloads_) {
      if (xy.second != ty) continue;
      auto img = find_codec(CodecId::lossless)->decode(entry.second);
      if (!img || img->width != g_.stored_size() || img->height != g_.stored_size())
        return make_error(ErrorCode::corrupt,
                          "part " + (dir_ / shard_part_name(entry.first)).string() +
                              " has no valid level-" + std::to_string(plan_.apex_level) + " tile " +
                              std::to_string(xy.first) + "/" + std::to_string(ty));
      tiles_.emplace(xy.first, std::move(img).value());
    }
    return {};
  }

  const ShardPlan& plan_;
  const Geometry& g_;
  std::filesystem::path dir_;
  int k_;
  std::uint32_t shard_row_ = UINT32_MAX, row_ = UINT32_MAX;
  std::map<std::pair<std::uint32_t, std::uint32_t>,
           std::pair<std::size_t, std::vector<std::uint8_t>>>
      payloads_;
  std::map<std::uint32_t, TileImage> tiles_;
  std::vector<std::uint64_t> hashes_;
  std::vector<bool> hashed_;
};

}  // namespace

Result<ShardReport> build_apex(const ShardPlan& plan, const ShardBuildOptions& so) {
  detail::use_image_inputs();
  const int A = plan.apex_level;
  if (A == 0)
    return make_error(ErrorCode::invalid_argument,
                      "the plan's shards make every level down to 0: it has no apex (merge the "
                      "shards alone)");
  auto geometry = detail::plan_geometry(plan);
  if (!geometry) return std::move(geometry).error();
  const Geometry& g = *geometry;
  const BuildOptions o = run_options(plan, so);
  std::vector<TileRect> emit = detail::plan_emit_rects(plan, g);
  for (std::size_t z = static_cast<std::size_t>(A); z < emit.size(); ++z) emit[z] = TileRect{};
  // Every shard's part must be there before any tile is built.
  for (std::size_t i = 0; i < plan.shards.size() && !o.synthetic; ++i) {
    if (Status st = check_part_file(so.out_dir / shard_part_name(i)); !st) return st.error();
  }
  detail::BuildRun run;
  run.options = &o;
  run.scratch_dir = so.out_dir;
  run.geometry = &g;
  run.codec = o.codec;
  run.threads = so.threads;
  detail::BuildPlan bp;
  ApexLevelRows rows(plan, g, so.out_dir);
  if (o.synthetic) {
    run.synthetic = emit;
  } else {
    // The whole build's level-A window, then a pass from it down to level 0.
    auto whole =
        detail::make_build_plan(g, o.downsample, detail::plan_window(plan, g), emit, UINT64_MAX);
    if (!whole) return std::move(whole).error();
    const TexelRect window =
        detail::pass_windows(g, o.downsample, whole->passes.front())[static_cast<std::size_t>(A)];
    detail::Pass pass{A,  0, window, -1,
                      -1, 0, 0,      std::vector<TileRect>(emit.begin(), emit.begin() + A + 1)};
    bp.rows = window.height();
    for (int z = 0; z < A; ++z) bp.tiles += emit[static_cast<std::size_t>(z)].count();
    bp.widest = window.width();
    bp.passes.push_back(std::move(pass));
    run.plan = &bp;
    run.readers.push_back([&rows](std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                                  std::uint32_t n,
                                  std::uint8_t* out) { return rows.read(x0, x1, y, n, out); });
  }
  return write_part(plan, run, so.out_dir / kApexPartName, std::nullopt, std::nullopt,
                    [&](json& m) -> Status {
                      if (o.synthetic) return {};
                      auto h = rows.hashes();
                      if (!h) return h.error();
                      m["shard_tiles"] = detail::shard_tiles_hash(*h);
                      return {};
                    });
}

Result<MergeReport> merge_plan(const ShardPlan& plan, const std::filesystem::path& parts_dir,
                               const std::filesystem::path& output,
                               const std::function<void(const archive::MergeProgress&)>& progress,
                               const std::atomic<bool>* cancel, bool verify) {
  return detail::merge_plan_scoped(plan, parts_dir, output, output, {}, progress, cancel, verify);
}

namespace detail {

Result<MergeReport> merge_plan_scoped(
    const ShardPlan& plan, const std::filesystem::path& parts_dir,
    const std::filesystem::path& output, const std::filesystem::path& named_after,
    const std::function<void(archive::MergeOptions&)>& scope,
    const std::function<void(const archive::MergeProgress&)>& progress,
    const std::atomic<bool>* cancel, bool verify) {
  const auto t0 = Clock::now();
  auto geometry = detail::plan_geometry(plan);
  if (!geometry) return std::move(geometry).error();
  archive::MergeOptions mo;
  if (plan.apex_level > 0) mo.parts.push_back(parts_dir / kApexPartName);
  for (std::size_t i = 0; i < plan.shards.size(); ++i)
    mo.parts.push_back(parts_dir / shard_part_name(i));
  // Every part a regular file that is not the output, before the output is created.
  const std::vector<std::filesystem::path> parts(mo.parts.begin(), mo.parts.end());
  if (Status st = check_output_is_not_an_input(output, parts); !st) return st.error();
  for (const std::filesystem::path& part : parts)
    if (Status st = check_part_file(part); !st) return st.error();
  auto p = detail::plan_prepared(plan);
  if (!p) return std::move(p).error();
  // Each part's manifest is checked against the plan while the merge reads the part's index (one
  // read of every index); the metadata a single `vts build` writes needs their content sums.
  std::uint64_t content_sum = 0;
  std::vector<std::uint64_t> attachments;  // each shard's, for the apex
  std::optional<json> apex;
  mo.check_part = [&](const archive::PartInfo& info) -> Status {
    auto sum = check_manifest(plan, info);
    if (!sum) return sum.error();
    content_sum += *sum;
    if (info.path.filename() == kApexPartName) {
      auto parsed = parse_json(info.manifest_json, "part " + info.path.string() + "'s manifest");
      if (!parsed) return parsed.error();
      apex = std::move(parsed).value();
    } else {
      attachments.push_back(detail::attachment_hash(info.attachment));
    }
    return {};
  };
  MergeReport report;
  mo.check_parts = [&](std::string& metadata_json) -> Status {
    if (apex)
      if (Status st = detail::check_apex_shards(plan, *apex, mo.parts.front(), attachments); !st)
        return st;
    report.info = detail::build_tileset_info(plan.options, *p, named_after, content_sum);
    metadata_json = report.info.to_json();
    return {};
  };
  mo.archive = detail::build_writer_options(*p, output);
  mo.on_progress = progress;
  mo.cancel = cancel;
  mo.verify = verify;
  if (scope) scope(mo);
  auto stats = archive::merge_parts(mo);
  if (!stats) return std::move(stats).error();
  report.stats = *stats;
  report.parts = mo.parts.size();
  report.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return report;
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
