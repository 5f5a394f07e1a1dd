#include "build_plan.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "cascade.hpp"

namespace vts {
inline namespace builder {
namespace detail {

namespace {

std::uint64_t rect_tiles(const std::vector<TileRect>& emit, int from, int to) {
  std::uint64_t n = 0;
  for (int z = from; z <= to; ++z) n += emit[static_cast<std::size_t>(z)].count();
  return n;
}

Status plan_window(const Geometry& g, DownsampleFilter filter, int finest, int coarsest,
                   const TexelRect& window, int source, const std::vector<TileRect>& emit,
                   std::uint64_t max_width, BuildPlan& plan) {
  if (window.width() <= max_width || finest == coarsest) {
    Pass p{
        finest, coarsest, window, source,
        -1,     0,        0,      std::vector<TileRect>(emit.begin(), emit.begin() + finest + 1)};
    plan.rows += window.height();
    plan.tiles += rect_tiles(p.emit, coarsest, finest);
    plan.widest = std::max(plan.widest, window.width());
    plan.passes.push_back(std::move(p));
    return {};
  }
  // The most levels a stripe can take: 2^s tiles and their halo within the limit.
  const std::uint64_t T = g.tile_size();
  int s = 0;
  while (s < finest - coarsest && (T << (s + 1)) + 2 * stripe_halo(g, s + 1, filter) <= max_width)
    ++s;
  if (s == 0)
    return make_error(ErrorCode::invalid_argument,
                      "a window of " + std::to_string(max_width) +
                          " texels cannot hold a stripe of two tiles and its halo (" +
                          std::to_string(2 * T + 2 * stripe_halo(g, 1, filter)) + " texels)");
  const int coarse = finest - s;
  TexelRect cw = window;
  for (int z = finest; z > coarse; --z) cw = coarser_window(g, z, cw, filter);
  const int scratch = static_cast<int>(plan.scratch.size());
  plan.scratch.push_back({coarse, cw});
  const std::uint64_t halo = stripe_halo(g, s, filter), block = T << s;
  for (std::uint64_t j = cw.x0 / T; j * T < cw.x1; ++j) {
    Pass p;
    p.finest = finest;
    p.coarsest = coarse;
    p.window = window;
    p.window.x0 = std::max(window.x0, j * block > halo ? j * block - halo : 0);
    p.window.x1 = std::min(window.x1, (j + 1) * block + halo);
    if (p.window.x0 >= p.window.x1) continue;  // nothing to read: its columns stay transparent
    p.source = source;
    p.scratch = scratch;
    p.core_x0 = std::max(j * T, cw.x0);
    p.core_x1 = std::min((j + 1) * T, cw.x1);
    p.emit.assign(static_cast<std::size_t>(finest) + 1, TileRect{});
    for (int z = coarse + 1; z <= finest; ++z) {
      TileRect e = emit[static_cast<std::size_t>(z)];
      const int shift = s - (finest - z);
      e.x0 = std::max<std::uint32_t>(e.x0, static_cast<std::uint32_t>(j << shift));
      e.x1 = std::min<std::uint32_t>(e.x1, static_cast<std::uint32_t>((j + 1) << shift));
      if (e.x0 < e.x1 && e.y0 < e.y1) p.emit[static_cast<std::size_t>(z)] = e;
    }
    plan.rows += p.window.height();
    plan.tiles += rect_tiles(p.emit, coarse + 1, finest);
    plan.widest = std::max(plan.widest, p.window.width());
    plan.passes.push_back(std::move(p));
  }
  return plan_window(g, filter, coarse, coarsest, cw, scratch, emit, max_width, plan);
}

}  // namespace

Result<BuildPlan> make_build_plan(const Geometry& g, DownsampleFilter filter,
                                  const TexelRect& window, const std::vector<TileRect>& emit,
                                  std::uint64_t max_width, int coarsest) {
  BuildPlan plan;
  if (Status st = plan_window(g, filter, g.max_zoom(), coarsest, window, -1, emit, max_width, plan);
      !st)
    return st.error();
  return plan;
}

std::vector<TexelRect> pass_windows(const Geometry& g, DownsampleFilter filter, const Pass& pass) {
  std::vector<TexelRect> w(static_cast<std::size_t>(pass.finest) + 1);
  w[static_cast<std::size_t>(pass.finest)] = pass.window;
  for (int z = pass.finest; z > pass.coarsest; --z)
    w[static_cast<std::size_t>(z - 1)] =
        coarser_window(g, z, w[static_cast<std::size_t>(z)], filter);
  return w;
}

Result<ScratchRaster> ScratchRaster::create(const std::filesystem::path& dir,
                                            const TexelRect& window) {
  const std::string where = dir.empty() ? std::string(".") : dir.string();
  int fd = ::open(where.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
  if (fd < 0 && (errno == EOPNOTSUPP || errno == EISDIR || errno == EINVAL)) {
    // A file system without O_TMPFILE: a named file, unlinked at once.
    std::string name = where + "/.vts-scratch-XXXXXX";
    fd = ::mkostemp(name.data(), O_CLOEXEC);
    if (fd >= 0) ::unlink(name.c_str());
  }
  if (fd < 0)
    return make_error(ErrorCode::io,
                      "cannot create a scratch file in " + where + ": " + std::strerror(errno));
  const auto bytes = static_cast<off_t>(window.width() * window.height() * 4);
  if (::ftruncate(fd, bytes) != 0) {
    const int e = errno;
    ::close(fd);
    return make_error(ErrorCode::io, "cannot size a scratch file of " + std::to_string(bytes) +
                                         " bytes in " + where + ": " + std::strerror(e));
  }
  return ScratchRaster(fd, window);
}

ScratchRaster::ScratchRaster(ScratchRaster&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)), window_(other.window_) {}

ScratchRaster::~ScratchRaster() {
  if (fd_ >= 0) ::close(fd_);
}

Status ScratchRaster::write(std::uint64_t y, std::uint64_t x0, std::uint64_t x1,
                            const std::uint8_t* texels) {
  const auto at = static_cast<off_t>(((y - window_.y0) * window_.width() + (x0 - window_.x0)) * 4);
  std::size_t n = (x1 - x0) * 4, done = 0;
  while (done < n) {
    const ssize_t w = ::pwrite(fd_, texels + done, n - done, at + static_cast<off_t>(done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0)
      return make_error(ErrorCode::io,
                        std::string("writing the build's scratch file: ") + std::strerror(errno));
    done += static_cast<std::size_t>(w);
  }
  return {};
}

Status ScratchRaster::read(std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t count,
                           std::uint8_t* out) const {
  const std::uint64_t w = x1 - x0;
  std::memset(out, 0, w * count * 4);
  const std::uint64_t c0 = std::max(x0, window_.x0), c1 = std::min(x1, window_.x1);
  for (std::uint32_t r = 0; r < count && c0 < c1; ++r) {
    const std::uint64_t row = y + r;
    if (row < window_.y0 || row >= window_.y1) continue;
    const auto at =
        static_cast<off_t>(((row - window_.y0) * window_.width() + (c0 - window_.x0)) * 4);
    std::uint8_t* dst = out + (r * w + (c0 - x0)) * 4;
    const std::size_t n = (c1 - c0) * 4;
    std::size_t done = 0;
    while (done < n) {
      const ssize_t got = ::pread(fd_, dst + done, n - done, at + static_cast<off_t>(done));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0)
        return make_error(ErrorCode::io, std::string("reading the build's scratch file: ") +
                                             (got == 0 ? "short" : std::strerror(errno)));
      done += static_cast<std::size_t>(got);
    }
  }
  return {};
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
