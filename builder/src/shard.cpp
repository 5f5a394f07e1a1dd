// Plans of sharded builds and the JSON they are kept in (vts/builder/shard.hpp).
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include <xxhash.h>

#include "build_core.hpp"
#include "input_drivers.hpp"
#include "shard_geo.hpp"
#include "shard_internal.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts {
inline namespace builder {

namespace {

using nlohmann::json;

const char* filter_choice_name(FilterChoice f) {
  switch (f) {
    case FilterChoice::none:
      return "none";
    case FilterChoice::gradient:
      return "gradient";
    default:
      return "auto";
  }
}

Result<FilterChoice> parse_filter_choice(const std::string& s) {
  if (s == "auto") return FilterChoice::automatic;
  if (s == "none") return FilterChoice::none;
  if (s == "gradient") return FilterChoice::gradient;
  return make_error(ErrorCode::invalid_argument, "unknown filter '" + s + "'");
}

json options_json(const BuildOptions& o) {
  json j;
  j["tile_size"] = o.tile_size;
  j["border"] = o.border;
  j["codec"] = codec_name(o.codec);
  j["zstd_level"] = o.encode.zstd_level;
  j["filter"] = filter_choice_name(o.encode.filter);
  j["bc1_quality"] = bc1_quality_name(o.encode.bc1);
  j["downsample"] = downsample_filter_name(o.downsample);
  j["grid"] = {o.grid_columns, o.grid_rows};
  j["name"] = o.name;
  j["description"] = o.description;
  if (o.synthetic) {
    const SyntheticSpec& s = *o.synthetic;
    j["synthetic"] = {{"width", s.width}, {"height", s.height}, {"region_level", s.region_level}};
    if (s.region)
      j["synthetic"]["region"] = {s.region->x0, s.region->y0, s.region->x1, s.region->y1};
  }
  detail::geo_options_to_json(o, j);
  return j;
}

Result<BuildOptions> options_from_json(const json& j) {
  BuildOptions o;
  o.tile_size = j.at("tile_size").get<std::uint32_t>();
  o.border = j.at("border").get<std::uint32_t>();
  auto codec = parse_codec_name(j.at("codec").get<std::string>());
  if (!codec) return codec.error();
  o.codec = *codec;
  o.encode.zstd_level = j.at("zstd_level").get<int>();
  auto filter = parse_filter_choice(j.at("filter").get<std::string>());
  if (!filter) return filter.error();
  o.encode.filter = *filter;
  auto bc1 = parse_bc1_quality(j.at("bc1_quality").get<std::string>());
  if (!bc1) return bc1.error();
  o.encode.bc1 = *bc1;
  auto down = parse_downsample_filter(j.at("downsample").get<std::string>());
  if (!down) return make_error(ErrorCode::invalid_argument, "unknown downsample filter");
  o.downsample = *down;
  o.grid_columns = j.at("grid").at(0).get<std::uint32_t>();
  o.grid_rows = j.at("grid").at(1).get<std::uint32_t>();
  o.name = j.at("name").get<std::string>();
  o.description = j.at("description").get<std::string>();
  if (j.contains("synthetic")) {
    const json& s = j["synthetic"];
    SyntheticSpec spec;
    spec.width = s.at("width").get<std::uint64_t>();
    spec.height = s.at("height").get<std::uint64_t>();
    spec.region_level = s.at("region_level").get<int>();
    if (s.contains("region")) {
      const json& r = s["region"];
      spec.region = TexelRect{r.at(0).get<std::uint64_t>(), r.at(1).get<std::uint64_t>(),
                              r.at(2).get<std::uint64_t>(), r.at(3).get<std::uint64_t>()};
    }
    o.synthetic = spec;
  }
  if (Status st = detail::geo_options_from_json(j, o); !st) return st.error();
  return o;
}

// The plan's JSON without its hash.
json plan_body(const ShardPlan& p) {
  json j;
  j["version"] = kPlanVersion;
  j["options"] = options_json(p.options);
  j["inputs"] = json::array();
  for (const PlanInput& in : p.inputs)
    j["inputs"].push_back(
        {{"path", in.path.string()}, {"size", in.size}, {"fingerprint", in.fingerprint}});
  j["input_description"] = p.input_description;
  j["geometry"] = {{"width", p.width}, {"height", p.height}, {"max_zoom", p.max_zoom}};
  if (!p.column_widths.empty()) {
    j["geometry"]["columns"] = p.column_widths;
    j["geometry"]["rows"] = p.row_heights;
  }
  j["split_level"] = p.split_level;
  j["apex_level"] = p.apex_level;
  // Only in plans of sets, so a one-archive plan keeps the hash it always had.
  if (p.archive_level > 0) j["archive_level"] = p.archive_level;
  if (p.geo) j["georeference"] = detail::geo_plan_to_json(*p.geo);
  json shards = json::array();
  for (const TileId& t : p.shards) shards.push_back({t.x, t.y});
  j["shards"] = std::move(shards);
  j["build_hash"] = detail::build_hash(j);
  return j;
}

std::string hash_hex(std::uint64_t h) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
  return text;
}

std::string body_hash(const json& body) {
  const std::string text = body.dump();
  return hash_hex(XXH3_64bits(text.data(), text.size()));
}

// The tiles of level z under `root` (a level-L tile) that a build writes.
TileRect subtree_rect(const TileRect& level, TileId root, int z) {
  const int d = z - root.z;
  TileRect r{root.x << d, root.y << d, (root.x + 1) << d, (root.y + 1) << d};
  r.x0 = std::max(r.x0, level.x0);
  r.y0 = std::max(r.y0, level.y0);
  r.x1 = std::max(r.x0, std::min(r.x1, level.x1));
  r.y1 = std::max(r.y0, std::min(r.y1, level.y1));
  return r;
}

// The level-L tiles whose sub-pyramid has tiles to build, in tile-id order.
std::vector<TileId> select_shards(const std::vector<TileRect>& emit, int L) {
  std::vector<TileId> shards;
  const TileRect& top = emit[static_cast<std::size_t>(L)];
  for (std::uint32_t y = top.y0; y < top.y1; ++y)
    for (std::uint32_t x = top.x0; x < top.x1; ++x) {
      const TileId root{static_cast<std::uint8_t>(L), x, y};
      for (std::size_t z = static_cast<std::size_t>(L); z < emit.size(); ++z)
        if (subtree_rect(emit[z], root, static_cast<int>(z)).count() > 0) {
          shards.push_back(root);
          break;
        }
    }
  std::sort(shards.begin(), shards.end(), [](TileId a, TileId b) {
    return archive::zxy_to_tile_id(a.z, a.x, a.y) < archive::zxy_to_tile_id(b.z, b.x, b.y);
  });
  return shards;
}

}  // namespace

namespace detail {

TileRect shard_rect(const TileRect& level, TileId root, int z) {
  return subtree_rect(level, root, z);
}

std::vector<TileRect> plan_emit_rects(const ShardPlan& plan, const Geometry& g) {
  auto p = plan_prepared(plan);
  if (!p) return std::vector<TileRect>(static_cast<std::size_t>(g.max_zoom()) + 1);
  return build_emit_rects(*p);
}

Result<Geometry> plan_geometry(const ShardPlan& plan) {
  return Geometry::create(plan.width, plan.height, plan.options.tile_size, plan.options.border);
}

}  // namespace detail

Result<std::string> input_fingerprint(const std::filesystem::path& path) {
  // A FIFO or a device at an input's path is refused, not read (it would block or never end).
  if (Status st = check_input_file(path); !st) return st.error();
  std::ifstream in(path, std::ios::binary);
  std::error_code ec;
  const std::uint64_t size = std::filesystem::file_size(path, ec);
  if (!in || ec) return make_error(ErrorCode::io, "cannot read input " + path.string());
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  XXH3_64bits_update(state, &size, sizeof size);
  std::vector<char> buf;
  auto sample = [&](std::uint64_t at, std::uint64_t n) {
    n = std::min(n, size - std::min(at, size));
    buf.resize(n);
    in.seekg(static_cast<std::streamoff>(at));
    in.read(buf.data(), static_cast<std::streamsize>(n));
    XXH3_64bits_update(state, buf.data(), static_cast<std::size_t>(in.gcount()));
  };
  constexpr std::uint64_t kMiB = std::uint64_t{1} << 20;
  sample(0, kMiB);
  sample(size > kMiB ? size - kMiB : 0, kMiB);
  for (std::uint64_t k = 0; k < 64; ++k) sample(size / 64 * k, 64 * 1024);
  const std::uint64_t h = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  if (in.bad()) return make_error(ErrorCode::io, "cannot read input " + path.string());
  return hash_hex(h);
}

Result<ShardPlan> make_shard_plan(const BuildOptions& o, std::optional<int> split_level,
                                  std::uint64_t min_shards, int apex_levels) {
  detail::use_image_inputs();
  if (apex_levels < 0)
    return make_error(ErrorCode::invalid_argument,
                      "--apex-levels " + std::to_string(apex_levels) + " is negative");
  auto prepared = detail::prepare_build(o);
  if (!prepared) return std::move(prepared).error();
  const Geometry& g = *prepared->geometry;
  ShardPlan plan;
  plan.options = o;
  plan.options.output.clear();
  plan.options.threads = 0;
  plan.options.on_progress = nullptr;
  plan.options.on_warning = nullptr;
  plan.options.cancel = nullptr;
  for (const auto& path : o.inputs) {
    PlanInput in{path, 0, {}};
    std::error_code ec;
    in.size = std::filesystem::file_size(path, ec);
    auto fp = input_fingerprint(path);
    if (!fp) return fp.error();
    in.fingerprint = *fp;
    plan.inputs.push_back(std::move(in));
  }
  plan.input_description = prepared->input_description;
  plan.geo = detail::pin_geo_plan(*prepared);
  plan.width = g.width();
  plan.height = g.height();
  plan.max_zoom = g.max_zoom();
  if (prepared->source) {
    plan.column_widths = prepared->source->column_widths();
    plan.row_heights = prepared->source->row_heights();
  }
  const std::vector<TileRect> emit = detail::build_emit_rects(*prepared);
  if (split_level) {
    if (*split_level < 0 || *split_level > g.max_zoom())
      return make_error(ErrorCode::invalid_argument,
                        "--split-level " + std::to_string(*split_level) + " is outside 0.." +
                            std::to_string(g.max_zoom()) + " (the max zoom of this build)");
    plan.split_level = *split_level;
    plan.shards = select_shards(emit, plan.split_level);
  } else {
    for (int L = 0; L <= g.max_zoom(); ++L) {
      plan.split_level = L;
      plan.shards = select_shards(emit, L);
      if (plan.shards.size() >= min_shards) break;
    }
  }
  plan.apex_level =
      std::min(plan.split_level + std::min(apex_levels, Geometry::kMaxZoom), plan.max_zoom);
  const json body = plan_body(plan);
  plan.build_hash = body.at("build_hash").get<std::string>();
  plan.hash = body_hash(body);
  return plan;
}

void set_archive_level(ShardPlan& plan, int k) {
  plan.archive_level = k;
  plan.hash = body_hash(plan_body(plan));
}

std::string plan_to_json(const ShardPlan& plan) {
  json j = plan_body(plan);
  j["hash"] = body_hash(j);
  return j.dump(1) + "\n";
}

Result<ShardPlan> plan_from_json(const std::string& text) {
  // Depth-limited and without exceptions; only the fields below are copied out of it.
  auto parsed = parse_json(text, "plan");
  if (!parsed) return std::move(parsed).error();
  try {
    json j = std::move(parsed).value();
    if (!j.is_object())
      return make_error(ErrorCode::invalid_argument, "not a vts plan: not an object");
    if (j.at("version").get<int>() != kPlanVersion)
      return make_error(ErrorCode::invalid_argument, "plan version " + j.at("version").dump() +
                                                         " is not " + std::to_string(kPlanVersion));
    const std::string hash = j.at("hash").get<std::string>();
    j.erase("hash");
    if (body_hash(j) != hash)
      return make_error(ErrorCode::corrupt, "plan hash " + hash + " does not match its content");
    ShardPlan p;
    auto o = options_from_json(j.at("options"));
    if (!o) return o.error();
    p.options = std::move(o).value();
    for (const json& in : j.at("inputs")) {
      p.inputs.push_back({in.at("path").get<std::string>(), in.at("size").get<std::uint64_t>(),
                          in.at("fingerprint").get<std::string>()});
      p.options.inputs.push_back(p.inputs.back().path);
    }
    p.input_description = j.at("input_description").get<std::string>();
    p.width = j.at("geometry").at("width").get<std::uint64_t>();
    p.height = j.at("geometry").at("height").get<std::uint64_t>();
    p.max_zoom = j.at("geometry").at("max_zoom").get<int>();
    if (j.at("geometry").contains("columns")) {
      p.column_widths = j["geometry"].at("columns").get<std::vector<std::uint64_t>>();
      p.row_heights = j["geometry"].at("rows").get<std::vector<std::uint64_t>>();
    }
    p.split_level = j.at("split_level").get<int>();
    p.apex_level = j.at("apex_level").get<int>();
    if (j.contains("archive_level")) {
      p.archive_level = j.at("archive_level").get<int>();
      if (p.archive_level < 1 || p.archive_level > p.max_zoom)
        return make_error(ErrorCode::invalid_argument,
                          "plan archive level " + std::to_string(p.archive_level) +
                              " is outside 1.." + std::to_string(p.max_zoom));
    }
    if (j.contains("georeference")) {
      auto geo = detail::geo_plan_from_json(j["georeference"]);
      if (!geo) return geo.error();
      p.geo = std::move(geo).value();
    }
    if (p.split_level < 0 || p.split_level > p.max_zoom || p.max_zoom > Geometry::kMaxZoom)
      return make_error(ErrorCode::invalid_argument, "plan split level is outside its levels");
    if (p.apex_level < p.split_level || p.apex_level > p.max_zoom)
      return make_error(ErrorCode::invalid_argument,
                        "plan apex level " + std::to_string(p.apex_level) + " is outside " +
                            std::to_string(p.split_level) + ".." + std::to_string(p.max_zoom));
    for (const json& s : j.at("shards"))
      p.shards.push_back({static_cast<std::uint8_t>(p.split_level), s.at(0).get<std::uint32_t>(),
                          s.at(1).get<std::uint32_t>()});
    p.build_hash = j.at("build_hash").get<std::string>();
    if (p.build_hash != detail::build_hash(j))
      return make_error(ErrorCode::corrupt,
                        "plan build hash " + p.build_hash + " does not match its content");
    p.hash = hash;
    return p;
  } catch (const json::exception& e) {
    return make_error(ErrorCode::invalid_argument, std::string("not a vts plan: ") + e.what());
  }
}

Result<ShardPlan> load_plan(const std::filesystem::path& path) {
  auto text = read_file(path);
  if (!text)
    return make_error(text.error().code,
                      "cannot read plan " + path.string() + ": " + text.error().message);
  auto plan = plan_from_json(*text);
  if (!plan) return make_error(plan.error().code, path.string() + ": " + plan.error().message);
  return plan;
}

Status save_plan(const ShardPlan& plan, const std::filesystem::path& path) {
  return write_file_atomically(path, plan_to_json(plan));
}

namespace {

void put_le(std::vector<std::uint8_t>& out, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

std::uint64_t get_le(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= std::uint64_t{p[i]} << (8 * i);
  return v;
}

}  // namespace

std::vector<std::uint8_t> encode_apex_tiles(const std::vector<ApexTile>& tiles) {
  std::vector<std::uint8_t> out;
  put_le(out, tiles.size(), 4);
  for (const ApexTile& t : tiles) {
    put_le(out, t.x, 4);
    put_le(out, t.y, 4);
    put_le(out, t.payload.size(), 8);
    out.insert(out.end(), t.payload.begin(), t.payload.end());
  }
  return out;
}

Result<std::vector<ApexTile>> decode_apex_tiles(const std::vector<std::uint8_t>& a) {
  auto bad = [](const std::string& why) {
    return make_error(ErrorCode::corrupt, "invalid level-A tiles attachment: " + why);
  };
  if (a.size() < 4) return bad("shorter than its count");
  const std::uint64_t count = get_le(a.data(), 4);
  std::vector<ApexTile> tiles;
  std::size_t at = 4;
  for (std::uint64_t i = 0; i < count; ++i) {
    if (a.size() - at < 16) return bad("tile " + std::to_string(i) + "'s header is cut short");
    ApexTile t;
    t.x = static_cast<std::uint32_t>(get_le(a.data() + at, 4));
    t.y = static_cast<std::uint32_t>(get_le(a.data() + at + 4, 4));
    const std::uint64_t n = get_le(a.data() + at + 8, 8);
    at += 16;
    if (n > a.size() - at) return bad("tile " + std::to_string(i) + "'s payload is cut short");
    t.payload.assign(a.begin() + static_cast<std::ptrdiff_t>(at),
                     a.begin() + static_cast<std::ptrdiff_t>(at + n));
    at += n;
    tiles.push_back(std::move(t));
  }
  if (at != a.size()) return bad(std::to_string(a.size() - at) + " bytes after its last tile");
  return tiles;
}

std::string shard_part_name(std::size_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "shard-%06zu.part", index);
  return name;
}

}  // namespace builder
}  // namespace vts
