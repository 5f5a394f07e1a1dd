#include "image_source.hpp"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string_view>

#include "vts/base/file_io.hpp"
#include "vts/builder/downsample.hpp"

namespace vts {
inline namespace builder {
namespace detail {

namespace OIIO = OIIO_NAMESPACE;

struct ImageSource::Piece {
  std::unique_ptr<OIIO::ImageInput> in;
  std::filesystem::path path;
  std::uint64_t width = 0, height = 0;
  int channels = 0;
  bool is_float = false;       // float/half data: linear light, converted with the sRGB OETF
  bool float_is_srgb = false;  // float data the file declares as sRGB-encoded
  // Tiled files are read one band of tile rows at a time with read_tiles(): OpenImageIO 2.4's
  // read_scanlines() on tiled TIFFs crashes (SIGFPE), and whole tile rows are what it would
  // decode anyway.
  int tile_width = 0, tile_height = 0;
  std::vector<std::uint8_t> band;
  std::int64_t band_y0 = -1;
  std::uint64_t band_x0 = 0, band_x1 = 0;

  // Reads columns [x0, x1) of rows [y, y + n) of channels [0, nch) as `type` into out (tightly
  // packed); an error when the reader fails or reports damage (check_read()). A tiled file
  // decodes only the tiles over those columns; a scanline file decodes whole rows.
  Status read(std::uint64_t x0, std::uint64_t x1, std::uint64_t y, std::uint32_t n, int nch,
              OIIO::TypeDesc type, void* out) {
    const std::string what = "reading rows " + std::to_string(y) + ".." + std::to_string(y + n);
    const std::size_t px = nch * type.size();
    const std::size_t out_row = (x1 - x0) * px;
    auto* dst = static_cast<std::uint8_t*>(out);
    if (tile_height <= 0) {
      const bool whole = x0 == 0 && x1 == width;
      if (!whole) band.resize(std::size_t{n} * width * px);
      // OpenImageIO 2.4's read_scanlines() stages every call in a fresh 64 MiB buffer (page
      // faults on the whole input, a tenth of a build's CPU) unless it may take its native path,
      // which it does not for a TIFF (its override converts): ask for the native rows directly
      // when they are what we want.
      const OIIO::ImageSpec& spec = in->spec();
      const bool native =
          type == spec.format && spec.channelformats.empty() && nch == spec.nchannels;
      void* dst_rows = whole ? out : band.data();
      const bool ok = native
                          ? in->read_native_scanlines(0, 0, static_cast<int>(y),
                                                      static_cast<int>(y + n), 0, dst_rows)
                          : in->read_scanlines(0, 0, static_cast<int>(y), static_cast<int>(y + n),
                                               0, 0, nch, type, dst_rows);
      band_y0 = -1;
      if (Status st = check_read(path, what, ok, in->geterror()); !st) return st;
      if (!whole)
        for (std::uint32_t r = 0; r < n; ++r)
          std::memcpy(dst + r * out_row, band.data() + (r * width + x0) * px, out_row);
      return {};
    }
    // The band holds tile columns [t0, t1) of one row of tiles.
    const std::uint64_t t0 = x0 / tile_width * tile_width;
    const std::uint64_t t1 = std::min<std::uint64_t>(
        width, (x1 + tile_width - 1) / static_cast<std::uint64_t>(tile_width) * tile_width);
    const std::size_t band_row = (t1 - t0) * px;
    for (std::uint64_t row = y; row < y + n;) {
      const auto b0 = static_cast<std::int64_t>(row / tile_height * tile_height);
      const auto b1 = std::min<std::int64_t>(b0 + tile_height, static_cast<std::int64_t>(height));
      if (b0 != band_y0 || t0 != band_x0 || t1 != band_x1) {
        band.resize(static_cast<std::size_t>(b1 - b0) * band_row);
        // A few tiles at a time: OpenImageIO stages a read_tiles() region in a buffer of its own,
        // which for a whole band would double the band's memory.
        const std::uint64_t chunk = std::uint64_t(tile_width) * 8;
        for (std::uint64_t c0 = t0; c0 < t1; c0 += chunk) {
          const std::uint64_t c1 = std::min(t1, c0 + chunk);
          const bool ok = in->read_tiles(
              0, 0, static_cast<int>(c0), static_cast<int>(c1), static_cast<int>(b0),
              static_cast<int>(b1), 0, 1, 0, nch, type, band.data() + (c0 - t0) * px,
              static_cast<OIIO::stride_t>(px), static_cast<OIIO::stride_t>(band_row));
          if (Status st = check_read(path, what, ok, in->geterror()); !st) {
            band_y0 = -1;  // the band is partly filled
            return st;
          }
        }
        band_y0 = b0;
        band_x0 = t0;
        band_x1 = t1;
      }
      const std::uint64_t take =
          std::min<std::uint64_t>(y + n, static_cast<std::uint64_t>(b1)) - row;
      for (std::uint64_t r = 0; r < take; ++r)
        std::memcpy(
            dst + r * out_row,
            band.data() + (row + r - static_cast<std::uint64_t>(b0)) * band_row + (x0 - t0) * px,
            out_row);
      dst += take * out_row;
      row += take;
    }
    return {};
  }
};

namespace {

// The decoder's messages, one per line, without repeats: the first few joined with "; ".
std::string condense(const std::string& messages) {
  std::vector<std::string> lines;
  std::size_t more = 0;
  for (std::size_t b = 0; b < messages.size();) {
    std::size_t e = messages.find('\n', b);
    if (e == std::string::npos) e = messages.size();
    std::string line = messages.substr(b, e - b);
    b = e + 1;
    if (line.empty() || std::find(lines.begin(), lines.end(), line) != lines.end()) continue;
    if (lines.size() < 3)
      lines.push_back(std::move(line));
    else
      ++more;
  }
  std::string out;
  for (const auto& l : lines) out += (out.empty() ? "" : "; ") + l;
  if (more > 0) out += " (and " + std::to_string(more) + " more)";
  return out;
}

// libjpeg's warnings about metadata (jerror.h): the pixels decode in full all the same.
bool harmless(std::string_view line) {
  for (std::string_view w :
       {"unknown JFIF revision number", "Invalid SOS parameters for sequential",
        "Unknown Adobe color transform code"})
    if (line.find(w) != std::string_view::npos) return true;
  return false;
}

// The decoder ran out of bytes: libjpeg, libpng and libtiff's words for it.
bool says_truncated(const std::string& messages) {
  for (std::string_view w : {"Premature end of", "end of file", "bytes, expected"})
    if (messages.find(w) != std::string::npos) return true;
  return false;
}

Result<std::unique_ptr<OIIO::ImageInput>> open_input(const std::filesystem::path& path) {
  // Not a FIFO or a device: OpenImageIO would wait for a writer, or read /dev/zero forever.
  if (Status s = check_input_file(path); !s) {
    if (s.error().code == ErrorCode::not_found)
      return make_error(ErrorCode::not_found, "input '" + path.string() + "' does not exist");
    return s.error();
  }
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) == 0 && !ec)
    return make_error(ErrorCode::truncated, "input '" + path.string() + "' is truncated: empty");
  // Texels are stored with straight alpha (docs/FORMAT.md): ask readers whose files hold straight
  // alpha (PNG, TIFF with unassociated extra samples) not to premultiply it on the way in.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path.string(), &config);
  if (!in) {
    const std::string why = OIIO::geterror();
    // A reader that recognises the file's signature (create() without opening checks it) but
    // cannot read its header: the file is damaged rather than of a kind we cannot read.
    auto reader = OIIO::ImageInput::create(path.string(), false);
    OIIO::geterror();  // create()'s own complaint, if any
    if (reader)
      return check_read(path, std::string("opening it as ") + reader->format_name(), false, why)
          .error();
    return make_error(ErrorCode::invalid_argument,
                      "cannot read input '" + path.string() +
                          "': " + (why.empty() ? "not an image format OpenImageIO can read" : why));
  }
  // Opening may already have reported damage (or a harmless warning, dropped here so that it is
  // not taken for a failure of the first read).
  if (Status st = check_read(path, "opening it", true, in->geterror()); !st) return st.error();
  return in;
}

}  // namespace

Status check_read(const std::filesystem::path& path, const std::string& what, bool ok,
                  const std::string& messages) {
  std::string damage;
  for (std::size_t b = 0; b < messages.size();) {
    std::size_t e = messages.find('\n', b);
    if (e == std::string::npos) e = messages.size();
    const std::string_view line(messages.data() + b, e - b);
    if (!line.empty() && !harmless(line)) damage.append(line).push_back('\n');
    b = e + 1;
  }
  if (ok && damage.empty()) return {};
  const ErrorCode code = says_truncated(damage) ? ErrorCode::truncated : ErrorCode::corrupt;
  return make_error(code, "input '" + path.string() + "' is " + error_code_name(code) + ": " +
                              what + " failed" +
                              (damage.empty() ? std::string() : ": " + condense(damage)));
}

ImageSource::~ImageSource() = default;

Result<std::unique_ptr<ImageSource>> ImageSource::open(
    const std::vector<std::filesystem::path>& inputs, std::uint32_t columns, std::uint32_t rows) {
  if (columns == 0 || rows == 0)
    return make_error(ErrorCode::invalid_argument, "grid must be at least 1x1");
  if (inputs.size() != std::size_t{columns} * rows)
    return make_error(ErrorCode::invalid_argument,
                      "grid " + std::to_string(columns) + "x" + std::to_string(rows) + " needs " +
                          std::to_string(columns * rows) + " inputs, got " +
                          std::to_string(inputs.size()));
  std::unique_ptr<ImageSource> src(new ImageSource());
  src->inputs_ = inputs;
  src->columns_ = columns;
  src->rows_ = rows;
  src->column_widths_.assign(columns, 0);
  src->row_heights_.assign(rows, 0);
  std::string first_desc;
  // Read every header once up front so inconsistencies fail before any work is done.
  for (std::uint32_t r = 0; r < rows; ++r) {
    for (std::uint32_t c = 0; c < columns; ++c) {
      const auto& path = inputs[std::size_t{r} * columns + c];
      auto in = open_input(path);
      if (!in) return std::move(in).error();
      const OIIO::ImageSpec& spec = (*in)->spec();
      if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.depth > 1)
        return make_error(ErrorCode::invalid_argument,
                          "input '" + path.string() + "' has no 2D pixels");
      const auto w = static_cast<std::uint64_t>(spec.width);
      const auto h = static_cast<std::uint64_t>(spec.height);
      if (src->column_widths_[c] == 0) src->column_widths_[c] = w;
      if (src->row_heights_[r] == 0) src->row_heights_[r] = h;
      if (src->column_widths_[c] != w || src->row_heights_[r] != h)
        return make_error(ErrorCode::invalid_argument,
                          "input '" + path.string() + "' is " + std::to_string(w) + "x" +
                              std::to_string(h) + " but grid column " + std::to_string(c) + " is " +
                              std::to_string(src->column_widths_[c]) + " wide and row " +
                              std::to_string(r) + " is " + std::to_string(src->row_heights_[r]) +
                              " high");
      if (first_desc.empty())
        first_desc = path.filename().string() + " " + std::to_string(w) + "x" + std::to_string(h) +
                     " " + std::to_string(spec.nchannels) + "ch " + spec.format.c_str();
    }
  }
  for (auto w : src->column_widths_) src->width_ += w;
  for (auto h : src->row_heights_) src->height_ += h;
  src->description_ = inputs.size() == 1
                          ? first_desc
                          : std::to_string(columns) + "x" + std::to_string(rows) + " mosaic " +
                                std::to_string(src->width_) + "x" + std::to_string(src->height_) +
                                " (first: " + first_desc + ")";
  return src;
}

Status ImageSource::open_row(std::uint32_t grid_row) {
  pieces_.clear();
  for (std::uint32_t c = 0; c < columns_; ++c) {
    const auto& path = inputs_[std::size_t{grid_row} * columns_ + c];
    auto in = open_input(path);
    if (!in) return std::move(in).error();
    auto piece = std::make_unique<Piece>();
    piece->in = std::move(in).value();
    piece->path = path;
    const OIIO::ImageSpec& spec = piece->in->spec();
    piece->width = static_cast<std::uint64_t>(spec.width);
    piece->height = static_cast<std::uint64_t>(spec.height);
    piece->channels = spec.nchannels;
    piece->tile_width = spec.tile_width;
    piece->tile_height = spec.tile_width > 0 ? spec.tile_height : 0;
    const auto base = spec.format.basetype;
    piece->is_float = base == OIIO::TypeDesc::FLOAT || base == OIIO::TypeDesc::HALF ||
                      base == OIIO::TypeDesc::DOUBLE;
    const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
    piece->float_is_srgb = cs == "sRGB" || cs == "srgb_rec709_scene";
    pieces_.push_back(std::move(piece));
  }
  open_row_ = grid_row;
  return {};
}

namespace {

// Rows of w texels of 3 or 4 8-bit channels (tightly packed) to RGBA8 rows `dst_stride` apart:
// the common case of read_window, as plain loops the compiler vectorises (a generic per-channel
// accessor cost a twentieth of a build).
void expand_rgb8(const std::uint8_t* src, int channels, std::uint64_t w, std::uint32_t n,
                 std::uint8_t* dst, std::size_t dst_stride) {
  for (std::uint32_t row = 0; row < n; ++row, dst += dst_stride) {
    if (channels == 4) {
      std::memcpy(dst, src, w * 4);
      src += w * 4;
      continue;
    }
    std::uint8_t* d = dst;
    for (std::uint64_t x = 0; x < w; ++x, src += 3, d += 4) {
      d[0] = src[0];
      d[1] = src[1];
      d[2] = src[2];
      d[3] = 255;
    }
  }
}

}  // namespace

Status ImageSource::read_rows(std::uint64_t y, std::uint32_t count, std::uint8_t* out) {
  return read_window(0, width_, y, count, out);
}

Status ImageSource::read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                                std::uint32_t count, std::uint8_t* out) {
  if (x0 >= x1 || x1 > width_) return make_error(ErrorCode::internal, "columns past the mosaic");
  const std::size_t dst_stride = (x1 - x0) * 4;
  // Split the request at grid-row boundaries.
  while (count > 0) {
    std::uint32_t r = 0;
    std::uint64_t row_start = 0;
    while (r < rows_ && y >= row_start + row_heights_[r]) row_start += row_heights_[r++];
    if (r >= rows_) return make_error(ErrorCode::internal, "row past the end of the mosaic");
    if (open_row_ != r) {
      if (auto st = open_row(r); !st) return st;
    }
    const std::uint64_t local_y = y - row_start;
    const auto n =
        static_cast<std::uint32_t>(std::min<std::uint64_t>(count, row_heights_[r] - local_y));
    std::uint64_t x_offset = 0;
    for (auto& piece : pieces_) {
      // The piece's columns within the window: pieces beside it are not decoded at all.
      const std::uint64_t left = x_offset;
      x_offset += piece->width;
      const std::uint64_t c0 = std::max(x0, left), c1 = std::min(x1, left + piece->width);
      if (c0 >= c1) continue;
      const std::uint64_t p0 = c0 - left, w = c1 - c0;
      const int ch = piece->channels;
      const int read_ch = std::min(ch, 4);
      const std::size_t texels = w * n;
      std::uint8_t* dst_base = out + (c0 - x0) * 4;
      auto expand = [&](auto get) {
        // get(i, c) returns channel c of texel i as 8-bit sRGB.
        for (std::uint32_t row = 0; row < n; ++row) {
          std::uint8_t* dst = dst_base + row * dst_stride;
          const std::size_t base = std::size_t{row} * w;
          for (std::uint64_t x = 0; x < w; ++x, dst += 4) {
            const std::size_t i = base + x;
            if (read_ch >= 3) {
              dst[0] = get(i, 0);
              dst[1] = get(i, 1);
              dst[2] = get(i, 2);
              dst[3] = read_ch == 4 ? get(i, 3) : 255;
            } else {  // grey, or grey + alpha
              dst[0] = dst[1] = dst[2] = get(i, 0);
              dst[3] = read_ch == 2 ? get(i, 1) : 255;
            }
          }
        }
      };
      Status ok;
      if (piece->is_float) {
        scratch_float_.resize(texels * read_ch);
        ok = piece->read(p0, p0 + w, local_y, n, read_ch, OIIO::TypeDesc::FLOAT,
                         scratch_float_.data());
        const bool srgb = piece->float_is_srgb;
        const float* f = scratch_float_.data();
        if (ok)
          expand([&](std::size_t i, int c) -> std::uint8_t {
            float v = f[i * read_ch + c];
            const bool alpha = (read_ch == 4 && c == 3) || (read_ch == 2 && c == 1);
            if (!(v > 0.0f)) return 0;
            if (v >= 1.0f) return 255;
            if (alpha || srgb) return static_cast<std::uint8_t>(std::lround(v * 255.0f));
            return encode_srgb8(v);
          });
      } else {
        scratch_.resize(texels * read_ch);
        ok = piece->read(p0, p0 + w, local_y, n, read_ch, OIIO::TypeDesc::UINT8, scratch_.data());
        const std::uint8_t* b = scratch_.data();
        if (ok && read_ch >= 3)
          expand_rgb8(b, read_ch, w, n, dst_base, dst_stride);
        else if (ok)
          expand([&](std::size_t i, int c) { return b[i * read_ch + c]; });
      }
      if (!ok) return ok;
    }
    out += std::size_t{n} * dst_stride;
    y += n;
    count -= n;
  }
  return {};
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
