// A scanline source over one image or a C x R mosaic of images, read through OpenImageIO and
// delivered as RGBA8 sRGB rows. Not thread-safe: one reader thread owns it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "vts/base/result.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// Decides whether an OpenImageIO read of `path` went wrong: `ok` is what the read call returned,
// `messages` what the reader reported meanwhile (ImageInput::geterror()). Decoders report damage
// in the middle of the pixels as a message on a call that still returns true (libjpeg's
// "Premature end of JPEG file", libtiff's short strip reads), so a read is good only when it
// returned true and every message is one of the few libjpeg warnings about metadata that leave
// the pixels intact (an unknown JFIF revision, non-standard SOS parameters, an unknown Adobe
// transform code). A bad read is truncated when the decoder ran out of bytes, corrupt otherwise,
// with `what` ("reading rows 0..64") and the decoder's first messages in the text.
Status check_read(const std::filesystem::path& path, const std::string& what, bool ok,
                  const std::string& messages);

class ImageSource {
 public:
  // Opens every input and checks the mosaic is consistent: inputs in one grid row share a height,
  // inputs in one grid column share a width. Inputs are given row-major. A file no reader
  // recognises is invalid_argument; a file in a recognised format whose header cannot be read,
  // or an empty file, is corrupt or truncated.
  static Result<std::unique_ptr<ImageSource>> open(const std::vector<std::filesystem::path>& inputs,
                                                   std::uint32_t columns, std::uint32_t rows);
  // Virtual, as the members below that the build calls: the build reaches this class through
  // input_drivers.hpp only, so a program that builds only synthetic pyramids links no OpenImageIO.
  virtual ~ImageSource();

  std::uint64_t width() const { return width_; }
  std::uint64_t height() const { return height_; }
  std::string description() const { return description_; }
  const std::vector<std::uint64_t>& column_widths() const { return column_widths_; }
  const std::vector<std::uint64_t>& row_heights() const { return row_heights_; }

  // Reads mosaic rows [y, y + count) as RGBA8 into out (width() * 4 bytes per row). Rows must be
  // read in increasing order. Damaged pixel data is an error (see check_read()), never rows of
  // whatever the decoder filled in.
  virtual Status read_rows(std::uint64_t y, std::uint32_t count, std::uint8_t* out);
  // Columns [x0, x1) of those rows ((x1 - x0) * 4 bytes per row): mosaic pieces beside the
  // columns are not read, and a tiled file decodes only the tiles over them (a shard's window).
  virtual Status read_window(std::uint64_t x0, std::uint64_t x1, std::uint64_t y,
                             std::uint32_t count, std::uint8_t* out);

 private:
  struct Piece;
  ImageSource() = default;
  Status open_row(std::uint32_t grid_row);

  std::vector<std::filesystem::path> inputs_;
  std::uint32_t columns_ = 1, rows_ = 1;
  std::vector<std::uint64_t> column_widths_, row_heights_;
  std::uint64_t width_ = 0, height_ = 0;
  std::string description_;
  // Only the pieces of the grid row being read are open, so a mosaic of many large files keeps
  // just one row of decoders alive.
  std::uint32_t open_row_ = UINT32_MAX;
  std::vector<std::unique_ptr<Piece>> pieces_;
  std::vector<std::uint8_t> scratch_;
  std::vector<float> scratch_float_;
};

}  // namespace detail
}  // namespace builder
}  // namespace vts
