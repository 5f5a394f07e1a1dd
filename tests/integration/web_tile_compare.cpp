// web_tile_compare: compares exported web tiles (T x T) with the tile contents `vts extract` wrote
// (w x h, clipped to the image), reading both through OpenImageIO — decoders independent of ours —
// in one process, so a test can check hundreds of tiles quickly.
//
//   web_tile_compare exact LIST      every texel equal, and every texel beyond w x h (0,0,0,0)
//   web_tile_compare rgba LIST MIN   PSNR over the w x h content, RGBA, >= MIN dB
//   web_tile_compare rgb LIST MIN    the same over R, G, B only (JPEG: no alpha)
// LIST: one "EXPORTED REFERENCE" pair a line. A 3-channel image reads as RGB with alpha 255; a
// REFERENCE named *.rgba is raw square RGBA8 (tests/integration/web_mercator_tile's output).
// Prints "tiles=N min_psnr=P worst=EXPORTED". Exit 0 when all pass, 1 otherwise (first failure on
// stderr), 2 on bad usage or an unreadable image.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

namespace {

namespace OIIO = OIIO_NAMESPACE;

struct Rgba {
  int width = 0, height = 0;
  std::vector<std::uint8_t> px;
};

bool load_raw(const std::string& path, Rgba& out) {
  std::ifstream in(path, std::ios::binary);
  out.px.assign(std::istreambuf_iterator<char>(in), {});
  const auto side = static_cast<int>(std::lround(std::sqrt(double(out.px.size()) / 4)));
  if (side == 0 || std::size_t(side) * side * 4 != out.px.size()) {
    std::fprintf(stderr, "%s is not square raw RGBA8\n", path.c_str());
    return false;
  }
  out.width = out.height = side;
  return true;
}

bool load(const std::string& path, Rgba& out) {
  if (path.size() > 5 && path.ends_with(".rgba")) return load_raw(path, out);
  OIIO::ImageBuf buf(path);
  if (!buf.read(0, 0, true, OIIO::TypeDesc::UINT8)) {
    std::fprintf(stderr, "cannot read %s: %s\n", path.c_str(), buf.geterror().c_str());
    return false;
  }
  const OIIO::ImageSpec& s = buf.spec();
  const int ch = s.nchannels;
  if (ch != 3 && ch != 4) {
    std::fprintf(stderr, "%s has %d channels\n", path.c_str(), ch);
    return false;
  }
  std::vector<std::uint8_t> raw(std::size_t(s.width) * s.height * ch);
  buf.get_pixels(buf.roi(), OIIO::TypeDesc::UINT8, raw.data());
  out.width = s.width;
  out.height = s.height;
  out.px.assign(std::size_t(s.width) * s.height * 4, 255);
  for (std::size_t i = 0; i < std::size_t(s.width) * s.height; ++i)
    for (int c = 0; c < ch; ++c) out.px[i * 4 + c] = raw[i * ch + c];
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (!((mode == "exact" && argc == 3) || ((mode == "rgba" || mode == "rgb") && argc == 4))) {
    std::fprintf(stderr, "usage: web_tile_compare (exact LIST | rgba LIST MIN | rgb LIST MIN)\n");
    return 2;
  }
  std::ifstream list(argv[2]);
  if (!list) {
    std::fprintf(stderr, "cannot read %s\n", argv[2]);
    return 2;
  }
  const double min_psnr = argc == 4 ? std::stod(argv[3]) : 0;
  const int channels = mode == "rgb" ? 3 : 4;
  std::string exported, reference, worst;
  double lowest = std::numeric_limits<double>::infinity();
  int tiles = 0, status = 0;
  while (list >> exported >> reference) {
    Rgba e, r;
    if (!load(exported, e) || !load(reference, r)) return 2;
    if (r.width > e.width || r.height > e.height) {
      std::fprintf(stderr, "%s is %dx%d, smaller than %s\n", exported.c_str(), e.width, e.height,
                   reference.c_str());
      return 1;
    }
    ++tiles;
    double sq = 0;
    for (int y = 0; y < e.height; ++y)
      for (int x = 0; x < e.width; ++x)
        for (int c = 0; c < 4; ++c) {
          const int ev = e.px[(std::size_t(y) * e.width + x) * 4 + c];
          const bool inside = x < r.width && y < r.height;
          const int rv = inside ? r.px[(std::size_t(y) * r.width + x) * 4 + c] : 0;
          if (mode == "exact" && ev != rv) {
            std::fprintf(stderr, "%s: texel (%d, %d) channel %d is %d, %s has %d\n",
                         exported.c_str(), x, y, c, ev,
                         inside ? reference.c_str() : "the transparent padding", rv);
            return 1;
          }
          if (inside && c < channels) sq += double(ev - rv) * (ev - rv);
        }
    const double mse = sq / (double(r.width) * r.height * channels);
    const double psnr =
        mse == 0 ? std::numeric_limits<double>::infinity() : 10 * std::log10(255.0 * 255.0 / mse);
    if (psnr < lowest) lowest = psnr, worst = exported;
    if (mode != "exact" && psnr < min_psnr && status == 0) {
      std::fprintf(stderr, "%s: PSNR %.2f dB < %.2f dB against %s\n", exported.c_str(), psnr,
                   min_psnr, reference.c_str());
      status = 1;
    }
  }
  std::printf("tiles=%d min_psnr=%.2f worst=%s\n", tiles, lowest, worst.c_str());
  return tiles == 0 ? 1 : status;
}
