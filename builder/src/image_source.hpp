// A scanline source over one image or a C x R mosaic of images, read through OpenImageIO and
// delivered as RGBA8 sRGB rows. Not thread-safe: one reader thread owns it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "vts/protocol/result.hpp"

namespace vts::detail {

class ImageSource {
 public:
  // Opens every input and checks the mosaic is consistent: inputs in one grid row share a height,
  // inputs in one grid column share a width. Inputs are given row-major.
  static Result<std::unique_ptr<ImageSource>> open(const std::vector<std::filesystem::path>& inputs,
                                                   std::uint32_t columns, std::uint32_t rows);
  ~ImageSource();

  std::uint64_t width() const { return width_; }
  std::uint64_t height() const { return height_; }
  std::string description() const { return description_; }

  // Reads mosaic rows [y, y + count) as RGBA8 into out (width() * 4 bytes per row). Rows must be
  // read in increasing order.
  Status read_rows(std::uint64_t y, std::uint32_t count, std::uint8_t* out);

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

}  // namespace vts::detail
