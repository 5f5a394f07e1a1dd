#include "progress.hpp"

#include <unistd.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace vts::cli {

ProgressBar::ProgressBar(std::string label, std::string unit, bool enabled)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      enabled_(enabled && stderr_is_terminal()),
      t0_(std::chrono::steady_clock::now()) {}

ProgressBar::~ProgressBar() {
  finish();
}

bool ProgressBar::stderr_is_terminal() {
  return ::isatty(STDERR_FILENO) == 1;
}

void ProgressBar::update(std::uint64_t done, std::uint64_t total, const std::string& extra) {
  if (!enabled_) return;
  const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  const double frac = total ? double(done) / double(total) : 0.0;
  const int width = 24;
  const int filled = static_cast<int>(frac * width);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(width, '.');
  const double rate = t > 0 ? double(done) / t : 0.0;
  std::string eta = "--";
  if (rate > 0 && done < total) eta = human_duration(double(total - done) / rate);
  std::fprintf(stderr, "\r\033[K%s [%s] %5.1f%% %llu/%llu %s  %.0f %s/s  ETA %s%s%s",
               label_.c_str(), bar.c_str(), frac * 100.0, (unsigned long long)done,
               (unsigned long long)total, unit_.c_str(), rate, unit_.c_str(), eta.c_str(),
               extra.empty() ? "" : "  ", extra.c_str());
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::finish() {
  if (drawn_) std::fprintf(stderr, "\r\033[K");
  drawn_ = false;
}

std::string human_bytes(std::uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double v = double(bytes);
  int u = 0;
  while (v >= 1024.0 && u < 4) {
    v /= 1024.0;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.1f %s", v, units[u]);
  return buf;
}

std::string human_duration(double s) {
  char buf[32];
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  else if (s < 3600)
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

bool parse_u64(std::string_view s, std::uint64_t& out) {
  if (s.empty() || s.size() > 19) return false;
  std::uint64_t v = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + std::uint64_t(c - '0');
  }
  out = v;
  return true;
}

const char* array_job_index_name() {
  for (const char* name :
       {"JOB_COMPLETION_INDEX", "SLURM_ARRAY_TASK_ID", "AWS_BATCH_JOB_ARRAY_INDEX"}) {
    const char* value = std::getenv(name);
    if (value && *value) return name;
  }
  return "";
}

Result<std::optional<std::uint64_t>> array_job_index(const std::string& what) {
  const char* name = array_job_index_name();
  if (!*name) return std::optional<std::uint64_t>();
  const char* value = std::getenv(name);
  std::uint64_t index = 0;
  if (!parse_u64(value, index))
    return make_error(ErrorCode::invalid_argument,
                      std::string("$") + name + "='" + value + "' is not a " + what);
  return std::optional<std::uint64_t>(index);
}

Result<std::uint64_t> parse_byte_size(const std::string& text, std::string_view flag) {
  auto bad = [&] {
    return make_error(ErrorCode::invalid_argument, std::string(flag) + " '" + text +
                                                       "' is not a positive size (e.g. 500M, 10G)");
  };
  std::size_t n = 0;
  while (n < text.size() && text[n] >= '0' && text[n] <= '9') ++n;
  std::uint64_t v = 0;
  if (!parse_u64(std::string_view(text).substr(0, n), v) || v == 0) return bad();
  std::string suffix = text.substr(n);
  for (auto& c : suffix) c = char(std::toupper(static_cast<unsigned char>(c)));
  int shift = 0;
  if (!suffix.empty()) {
    const std::string units = "KMGT";
    const std::size_t u = units.find(suffix[0]);
    if (u == std::string::npos) return suffix == "B" ? Result<std::uint64_t>(v) : bad();
    shift = 10 * int(u + 1);
    const std::string rest = suffix.substr(1);
    if (!rest.empty() && rest != "B" && rest != "IB") return bad();
  }
  if (shift && v > (~std::uint64_t{0} >> shift)) return bad();
  return v << shift;
}

Result<std::pair<int, int>> parse_level_range(const std::string& text, std::string_view flag) {
  auto bad = [&](const std::string& why) {
    return make_error(ErrorCode::invalid_argument, std::string(flag) + " '" + text + "' " + why +
                                                       " (expected A-B or A, e.g. 0-5)");
  };
  const std::size_t dash = text.find('-');
  std::uint64_t a = 0, b = 0;
  const std::string_view t = text;
  if (dash == std::string::npos) {
    if (!parse_u64(t, a)) return bad("is not a level range");
    b = a;
  } else if (!parse_u64(t.substr(0, dash), a) || !parse_u64(t.substr(dash + 1), b)) {
    return bad("is not a level range");
  }
  if (a > std::uint64_t(Geometry::kMaxZoom) || b > std::uint64_t(Geometry::kMaxZoom))
    return bad("names a level beyond " + std::to_string(Geometry::kMaxZoom));
  if (a > b) return bad("is empty: the first level is after the last");
  return std::pair<int, int>{int(a), int(b)};
}

Result<TexelRect> parse_texel_rect(const std::string& text, std::string_view flag) {
  std::uint64_t v[4];
  std::size_t start = 0;
  for (int i = 0; i < 4; ++i) {
    const std::size_t comma = i < 3 ? text.find(',', start) : text.size();
    if (comma == std::string::npos ||
        !parse_u64(std::string_view(text).substr(start, comma - start), v[i]))
      return make_error(ErrorCode::invalid_argument,
                        std::string(flag) + " '" + text +
                            "' is not of the form x0,y0,x1,y1 (finest-level texels)");
    start = comma + 1;
  }
  TexelRect r{v[0], v[1], v[2], v[3]};
  if (r.empty())
    return make_error(
        ErrorCode::invalid_argument,
        std::string(flag) + " '" + text + "' is empty (x1 must exceed x0 and y1 exceed y0)");
  return r;
}

Result<std::vector<double>> parse_numbers(const std::string& text, std::size_t count,
                                          std::string_view flag, std::string_view form) {
  std::vector<double> v;
  std::size_t start = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t comma = i + 1 < count ? text.find(',', start) : text.size();
    const std::string part =
        comma == std::string::npos ? std::string() : text.substr(start, comma - start);
    char* stop = nullptr;
    const double d = part.empty() ? 0.0 : std::strtod(part.c_str(), &stop);
    if (part.empty() || *stop != '\0' || !std::isfinite(d))
      return make_error(ErrorCode::invalid_argument, std::string(flag) + " '" + text +
                                                         "' is not of the form " +
                                                         std::string(form) + " (degrees)");
    v.push_back(d);
    start = comma + 1;
  }
  return v;
}

}  // namespace vts::cli
