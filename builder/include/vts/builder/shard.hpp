// Sharded builds (`vts plan`, `vts build --plan`, `vts merge`; docs/PLANET.md, "Plans, shards and
// parts"): a plan fixes a whole build once (options, inputs with their fingerprints, geometry) and
// cuts its pyramid at a split level L: the sub-pyramid under each level-L tile that has tiles to
// build is a shard (one contiguous tile-id range per level, archive::subtree_tile_ids). A shard
// stops at the apex level A = min(L + k, max zoom) (k: the apex levels, 2 by default): it writes
// its levels >= A to one part (archive::PartWriter) and keeps its level-A tiles lossless as the
// part's attachment (encode_apex_tiles); the apex builds the levels < A from those, so it equals a
// whole build's levels < A for every codec; merge_parts() then writes the archive a single
// `vts build` of the same options writes, byte for byte.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vts/archive/archive_set.hpp"
#include "vts/archive/pmtiles_part.hpp"
#include "vts/builder/builder.hpp"

namespace vts {
inline namespace builder {

inline constexpr int kPlanVersion = 3;

// The apex levels k a plan takes by default (shards stop at level min(L + k, max zoom)).
inline constexpr int kDefaultApexLevels = 2;

struct PlanInput {
  std::filesystem::path path;
  std::uint64_t size = 0;
  // XXH3-64 of the size and of the file's first and last MiB and 64 KiB at each 1/64 of it
  // (input_fingerprint): stable across copies, cheap on terabytes, changes when pixels change
  // in all but contrived cases.
  std::string fingerprint;
};

// A georeferenced build's choices (georeferenced inputs, or --synthetic with --tiling/--bounds):
// what a whole build resolves from all its inputs, pinned so that a shard opening only the inputs
// that meet its window builds the very same grid (shard_geo.cpp).
struct GeoPlan {
  Georeference
      georeference;  // tiling, bounds (the union of the inputs' extents, or --bounds), center
  // Georeferenced inputs only: the finest level, the value mapping (--range auto's percentiles
  // included; empty: values as they are), and each input's extent in degrees (clipped to the
  // scheme), in the inputs' order.
  bool inputs = false;
  int max_level = 0;
  std::vector<std::pair<double, double>> value_ranges;
  std::vector<LonLatBounds> input_bounds;
};

struct ShardPlan {
  // The build: BuildOptions' inputs, grid, synthetic spec, tile size, border, codec, encode
  // options, downsample filter, name and description (output, threads and callbacks are not part
  // of a plan).
  BuildOptions options;
  std::vector<PlanInput> inputs;
  std::string input_description;  // as `vts build` describes them ("earth.jpg 2048x1024 ...")
  std::uint64_t width = 0, height = 0;
  // The widths of the --grid's columns and heights of its rows, in texels (one each for a plain
  // image; none for a synthetic source): where each input lies in the image.
  std::vector<std::uint64_t> column_widths, row_heights;
  int max_zoom = 0;
  int split_level = 0;
  // A = min(L + k, max_zoom): shards write levels >= A, the apex levels < A (none when A = 0).
  int apex_level = 0;
  // The output is a set of archives (archive/archive_set.hpp) cut at this level K >= 1: one per
  // level-K tile, plus the top. 0: one archive. Not part of the build hash: parts do not depend on
  // it, so a plan may be given one (vts plan --archive-level) after its shards are built.
  int archive_level = 0;
  std::optional<GeoPlan> geo;
  std::vector<TileId> shards;  // level-L tiles, in Hilbert tile-id order; shard I is shards[I]
  // 16 hex digits: XXH3-64 of the plan without its inputs (paths, sizes, fingerprints; their
  // count is kept), input description and hashes: what every part must have been built with.
  // Parts record it and the fingerprints of the inputs they read (shard_update.cpp), so a plan
  // updated with new inputs (update_shard_plan) keeps the parts of unchanged shards.
  std::string build_hash;
  std::string hash;  // 16 hex digits: XXH3-64 of to_json() without the hash
};

// The fingerprint of PlanInput (16 hex digits).
Result<std::string> input_fingerprint(const std::filesystem::path& path);

// Resolves the geometry from the options' inputs and picks the split level: `split_level` when
// set, else the smallest level with at least `min_shards` shards (capped at the max zoom); the
// apex level is min(L + apex_levels, max zoom) (apex_levels >= 0; 0: shards stop at L).
Result<ShardPlan> make_shard_plan(const BuildOptions& options, std::optional<int> split_level,
                                  std::uint64_t min_shards, int apex_levels = kDefaultApexLevels);

// A shard part's attachment: its level-A tiles, lossless (docs/PLANET.md). Little-endian: a u32
// count, then per tile u32 x, u32 y, u64 length and `length` bytes of the lossless payload
// (the stored tile, borders included), in increasing (y, x).
struct ApexTile {
  std::uint32_t x = 0, y = 0;
  std::vector<std::uint8_t> payload;
};
std::vector<std::uint8_t> encode_apex_tiles(const std::vector<ApexTile>& tiles);
// invalid data (truncated, lengths past the end, bytes left over): corrupt.
Result<std::vector<ApexTile>> decode_apex_tiles(const std::vector<std::uint8_t>& attachment);

// The canonical JSON (keys sorted, hash included) and back; plan_from_json checks the version
// and the hash.
std::string plan_to_json(const ShardPlan& plan);
Result<ShardPlan> plan_from_json(const std::string& json);
Result<ShardPlan> load_plan(const std::filesystem::path& path);
Status save_plan(const ShardPlan& plan, const std::filesystem::path& path);

// What a plan's parts and archive will take on disk, estimated from its geometry and codec alone
// (docs/PLANET.md, "Bytes"; deploy/batch/k8s/render.sh sizes its volume with the same rule): the
// tiles of each level, dense, times bytes per stored tile. Not part of the plan (its hash covers
// every field): computed from it when needed, e.g. to refuse an output folder without the room.
struct PlanSizeEstimate {
  std::uint64_t tile_bytes = 0;  // per stored S x S tile
  std::uint64_t shard_max = 0;   // the largest shard's part
  std::uint64_t apex = 0;        // the apex part (0: no apex)
  std::uint64_t archive = 0;     // the merged archive
};
PlanSizeEstimate estimate_plan_size(const ShardPlan& plan);
// Bytes per stored tile: lossless as measured, scaled by S^2 / 264^2; bc1 S^2 / 2 (its stored size,
// an upper bound).
std::uint64_t estimate_plan_size_tile_bytes(const ShardPlan& plan);
// Shard `index`'s part: its sub-pyramid's tiles of levels >= the apex level (clipped to the
// image) plus its level-A tiles again, lossless, as the attachment; 0 for an index past the
// plan's shards.
std::uint64_t estimate_shard_part_bytes(const ShardPlan& plan, std::size_t index);

// "shard-000012.part", "apex.part".
std::string shard_part_name(std::size_t index);
inline constexpr const char* kApexPartName = "apex.part";

struct ShardBuildOptions {
  std::filesystem::path out_dir;
  unsigned threads = 0;
  std::function<void(const BuildProgress&)> on_progress;
  const std::atomic<bool>* cancel = nullptr;
};

struct ShardReport {
  std::filesystem::path part;
  std::optional<TileId> root;  // nullopt for the apex
  std::uint64_t tiles = 0;
  // Finest-level texels the shard read (its window: core plus halo) and its own (core) texels.
  std::uint64_t texels_read = 0, core_texels = 0;
  std::uint64_t content_sum = 0;
  // The inputs the shard opened: those whose extent meets its window (all, for plain images).
  std::size_t inputs_opened = 0;
  archive::PartStats stats;
  double seconds = 0;
};

// Builds shard `index` of the plan into out_dir/shard_part_name(index).
Result<ShardReport> build_shard(const ShardPlan& plan, std::size_t index,
                                const ShardBuildOptions& options);
// Builds the levels above the apex level into out_dir/apex.part from the shards' parts there.
// apex_level 0 has no apex: invalid_argument.
Result<ShardReport> build_apex(const ShardPlan& plan, const ShardBuildOptions& options);

// The finest-level texels shard `index` owns (its core) and those it reads (its window: the core
// widened by the halo its borders and downsampling filter reach, clipped to the image).
struct ShardWindow {
  TexelRect core, window;
};
Result<ShardWindow> shard_window(const ShardPlan& plan, std::size_t index);

// Where input `input` lies in the image (finest-level texels): its cell of the grid.
TexelRect input_rect(const ShardPlan& plan, std::size_t input);

// The inputs whose cell meets shard `index`'s window (none for a synthetic plan), ascending.
std::vector<std::size_t> shard_inputs(const ShardPlan& plan, std::size_t index);

// The shards whose window meets any of the inputs `changed` (indexes into plan.inputs), ascending.
std::vector<std::size_t> affected_shards(const ShardPlan& plan,
                                         const std::vector<std::size_t>& changed);

struct PlanUpdate {
  ShardPlan plan;                           // the new plan: the old one with the new inputs
  std::vector<std::size_t> changed_inputs;  // whose size or fingerprint differ, ascending
  std::vector<std::size_t> shards;          // to rebuild (affected_shards), ascending
  bool apex = false;                        // the apex must be rebuilt (some shard is)
};

// `vts plan --update`: the old plan with `inputs` (empty: its own paths, read again), keeping its
// options, geometry, grid, split and apex levels and shards; a change to any of these (an input of
// another size, another count of inputs) is invalid_argument naming it.
Result<PlanUpdate> update_shard_plan(const ShardPlan& old,
                                     const std::vector<std::filesystem::path>& inputs);

struct MergeReport {
  TilesetInfo info;
  archive::WriterStats stats;
  std::size_t parts = 0;
  double seconds = 0;
};

// Merges the plan's parts in `parts_dir` into `output`: the archive `vts build` writes.
// verify: archive::MergeOptions::verify (check every payload, or copy in the kernel).
Result<MergeReport> merge_plan(const ShardPlan& plan, const std::filesystem::path& parts_dir,
                               const std::filesystem::path& output,
                               const std::function<void(const archive::MergeProgress&)>& progress,
                               const std::atomic<bool>* cancel, bool verify = true);

// ---- Sets (archive/archive_set.hpp; docs/PLANET.md, "The planet as a set")

// The archives of the plan's set, in the manifest's order: the top (nullopt), then each tile of
// level K = plan.archive_level that the image covers and some shard reaches, in tile-id order.
// Empty for a plan of one archive (archive_level 0). `vts merge --archive I` merges entry I.
std::vector<std::optional<TileId>> set_archive_roots(const ShardPlan& plan);
// Makes the plan's output a set cut at level k (0: one archive) and updates its hash (its build
// hash stays: the parts do not depend on the archive level).
void set_archive_level(ShardPlan& plan, int k);

// What the largest archive of a set cut at level k would take (estimate_plan_size's rule, dense
// within each archive's sub-pyramid), and the smallest k >= 1 whose largest archive is at most
// max_bytes (invalid_argument when even the finest level's archives are larger).
std::uint64_t estimate_set_archive_max(const ShardPlan& plan, int k);
Result<int> archive_level_for_size(const ShardPlan& plan, std::uint64_t max_bytes);

struct SetArchiveReport {
  std::size_t index = 0;
  std::string name;            // the archive's file name in the set's folder
  std::optional<TileId> root;  // nullopt for the top
  bool empty = false;          // no tile of the parts lies in it: nothing but a marker written
  MergeReport merge;
};

// Merges archive `index` of the plan's set (set_archive_roots) from the parts in parts_dir into
// out_dir/<name>: merge_plan restricted to the archive's tiles, zooms and bounds, so each tile is
// byte for byte the one-file archive's. An archive in which the parts have no tile (a sparse
// plan) writes the marker out_dir/<name>.empty instead, so write_set_manifest() can tell it from
// one not merged yet.
Result<SetArchiveReport> merge_set_archive(
    const ShardPlan& plan, const std::filesystem::path& parts_dir,
    const std::filesystem::path& out_dir, std::size_t index,
    const std::function<void(const archive::MergeProgress&)>& progress,
    const std::atomic<bool>* cancel, bool verify = true);

// Writes out_dir/tileset.json (atomically) naming every archive of the set merged there, then
// removes the .empty markers. An archive neither there nor marked empty is not_found naming it
// and the `vts merge --archive` index that makes it; an archive that is not the plan's
// (another build) is invalid_argument.
Result<archive::SetManifest> write_set_manifest(const ShardPlan& plan,
                                                const std::filesystem::path& out_dir);

struct JoinProgress {
  std::uint64_t tiles_done = 0, tiles_total = 0;
};
// `vts merge --join`: every tile of the set at `set` (its folder or manifest) into one archive at
// `output`, the archive a one-file merge of the same parts writes, byte for byte.
Result<archive::WriterStats> join_set(const std::filesystem::path& set,
                                      const std::filesystem::path& output,
                                      const std::function<void(const JoinProgress&)>& progress,
                                      const std::atomic<bool>* cancel);

}  // namespace builder
}  // namespace vts
