// Fuzz target for the `vts` command line: the input, split on '\n', is the argument list after
// "vts". It is parsed by the real subcommands (every cli/src/cmd_*.cpp linked in, nothing run),
// and the option values the runners parse themselves (--grid, --synthetic, --region, --levels,
// --cache-size, --ram-size) go through the shared parsers of cli/src/progress.hpp. Invariants:
// a refused command line is a CLI::ParseError or an Error value (never another exception, never a
// crash), and whatever is accepted is within the bounds the help promises: --threads <= 1024,
// --zstd-level 1..19, --region-level 0..26, --slots 2..2^20, --name not empty, a WxH pair of two
// unsigned decimal 32-bit numbers, a byte size > 0 made of digits and a unit, levels A <= B <= 26.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"

namespace {

using namespace vts::cli;

void check(bool ok) {
  if (!ok) std::abort();  // an invariant broke: let the fuzzer record the input
}

bool all_digits(std::string_view s) {
  if (s.empty()) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  return true;
}

// An accepted numeric option must be within [lo, hi].
void check_range(CLI::App* sub, const char* flag, long long lo, long long hi) {
  CLI::Option* o = sub->get_option_no_throw(flag);
  if (o == nullptr || o->count() == 0) return;
  const auto v = o->as<long long>();
  check(v >= lo && v <= hi);
}

void check_accepted(CLI::App& app) {
  for (CLI::App* sub : app.get_subcommands()) {
    check_range(sub, "--threads", 0, 1024);
    check_range(sub, "--zstd-level", 1, 19);
    check_range(sub, "--region-level", 0, 26);
    check_range(sub, "--slots", 2, 1 << 20);
    if (CLI::Option* o = sub->get_option_no_throw("--name");
        o && o->count() && sub->get_name() == "build")
      check(!o->as<std::string>().empty());
  }
}

// The parsers the runners apply to an option's text.
void check_value(std::string_view flag, const std::string& v) {
  if (flag == "--grid" || flag == "--synthetic") {
    std::uint32_t a = 0, b = 0;
    if (parse_pair(v, 'x', a, b)) {
      const std::size_t x = v.find('x');
      check(all_digits(std::string_view(v).substr(0, x)) &&
            all_digits(std::string_view(v).substr(x + 1)));
      check(std::strtoull(v.c_str(), nullptr, 10) == a &&
            std::strtoull(v.c_str() + x + 1, nullptr, 10) == b);
    }
  } else if (flag == "--cache-size" || flag == "--ram-size") {
    auto r = parse_byte_size(v, flag);
    if (r)
      check(*r > 0 && !v.empty() && v[0] >= '0' && v[0] <= '9');
    else
      check(r.error().code == vts::ErrorCode::invalid_argument &&
            r.error().message.find(flag) != std::string::npos);
  } else if (flag == "--region") {
    auto r = parse_texel_rect(v, flag);
    if (r)
      check(r->x0 < r->x1 && r->y0 < r->y1);
    else
      check(r.error().code == vts::ErrorCode::invalid_argument);
  } else if (flag == "--levels") {
    auto r = parse_level_range(v, flag);
    if (r)
      check(0 <= r->first && r->first <= r->second && r->second <= 26);
    else
      check(r.error().code == vts::ErrorCode::invalid_argument);
  } else if (flag == "--listen" || flag == "--admin") {
    auto r = parse_endpoint(v);
    if (!r) check(r.error().code == vts::ErrorCode::invalid_argument);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::string> args;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  for (std::size_t start = 0; start <= text.size() && args.size() < 64;) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    args.emplace_back(text.substr(start, end - start));
    start = end + 1;
  }
  for (std::size_t i = 0; i + 1 < args.size(); ++i) check_value(args[i], args[i + 1]);

  CLI::App app{"vts", "vts"};
  app.require_subcommand(1);
  std::vector<Runner> runners;  // kept, never run
  runners.push_back(add_build(app));
  runners.push_back(add_plan(app));
  runners.push_back(add_merge(app));
  runners.push_back(add_extract(app));
  runners.push_back(add_export(app));
  runners.push_back(add_info(app));
  runners.push_back(add_verify(app));
  runners.push_back(add_serve(app));
  runners.push_back(add_sign(app));
  runners.push_back(add_cache(app));
  runners.push_back(add_warm(app));
  runners.push_back(add_loadtest(app));
#ifdef VTS_HAVE_ACCURACY
  runners.push_back(add_bench(app));
#endif
#ifdef VTS_HAVE_VIEWER
  runners.push_back(add_view(app));
#endif
  std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 pops from the back
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError&) {
    return 0;  // --help, --version and every refusal
  }
  check_accepted(app);
  return 0;
}
