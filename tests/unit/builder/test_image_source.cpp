// Input integrity at the ImageSource level: a truncated or corrupt PNG, JPEG or TIFF is an error
// naming the file and what failed (truncated or corrupt), never rows the decoder filled in; inputs
// that only carry harmless oddities still read in full.
#include "image_source.hpp"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "vts/builder/image_io.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts {
namespace {

namespace fs = std::filesystem;
namespace OIIO = OIIO_NAMESPACE;
using detail::ImageSource;
using TempDir = vts::test::TempDir;

constexpr int kSide = 512;

// A kSide x kSide RGB image of smooth gradients plus noise: big enough that every format spends
// most of its bytes on pixel data, so a cut at half the file lands in the pixels.
void write_image(const fs::path& p, const std::string& extra = {}) {
  std::mt19937 rng(7);
  std::vector<std::uint8_t> px(std::size_t{kSide} * kSide * 3);
  for (std::size_t y = 0; y < kSide; ++y)
    for (std::size_t x = 0; x < kSide; ++x)
      for (std::size_t c = 0; c < 3; ++c)
        px[(y * kSide + x) * 3 + c] = static_cast<std::uint8_t>((x + y * (c + 1)) / 4 + rng() % 64);
  auto out = OIIO::ImageOutput::create(p.string());
  ASSERT_TRUE(out) << p;
  OIIO::ImageSpec spec(kSide, kSide, 3, OIIO::TypeDesc::UINT8);
  if (extra == "tiled") spec.tile_width = spec.tile_height = 64;
  ASSERT_TRUE(out->open(p.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data())) << out->geterror();
  ASSERT_TRUE(out->close());
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

void spit(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

// Opens `inputs` as a columns x 1 mosaic and reads every row: the first error, or ok.
Status read_all(const std::vector<fs::path>& inputs, std::uint32_t columns = 1) {
  auto src = ImageSource::open(inputs, columns, 1);
  if (!src) return src.error();
  std::vector<std::uint8_t> rows((*src)->width() * 4 * 16);
  for (std::uint64_t y = 0; y < (*src)->height(); y += 16)
    if (Status st = (*src)->read_rows(y, 16, rows.data()); !st) return st;
  return {};
}

// `st` is an error of code `code` whose message names `file` and contains `text`.
void expect_damaged(const Status& st, ErrorCode code, const fs::path& file,
                    const std::string& text) {
  ASSERT_FALSE(st.ok()) << file << " read without an error";
  EXPECT_EQ(st.error().code, code) << st.error().message;
  EXPECT_NE(st.error().message.find("'" + file.string() + "'"), std::string::npos)
      << st.error().message;
  EXPECT_NE(st.error().message.find(text), std::string::npos) << st.error().message;
}

TEST(ImageSource, IntactInputsOfEveryFormatReadInFull) {
  TempDir dir;
  for (const char* name : {"a.png", "a.jpg", "a.tif"}) {
    write_image(dir / name);
    EXPECT_TRUE(read_all({dir / name}).ok()) << name;
  }
  write_image(dir / "t.tif", "tiled");
  EXPECT_TRUE(read_all({dir / "t.tif"}).ok());
}

TEST(ImageSource, TruncatedPixelDataIsAnErrorNotFilledRows) {
  TempDir dir;
  write_image(dir / "t.tif", "tiled");
  for (const char* name : {"a.png", "a.jpg", "a.tif", "t.tif"}) {
    if (std::string(name) != "t.tif") write_image(dir / name);
    const std::string bytes = slurp(dir / name);
    for (std::size_t cut : {bytes.size() / 2, bytes.size() * 9 / 10}) {
      const fs::path cut_path = dir / ("cut-" + std::to_string(cut) + "-" + name);
      spit(cut_path, bytes.substr(0, cut));
      // libjpeg fills the missing rows with grey and only warns ("Premature end of JPEG file");
      // libtiff's short strip read leaves read_scanlines() returning true.
      const Status st = read_all({cut_path});
      if (cut_path.extension() == ".tif" && !st.ok() && st.error().code == ErrorCode::corrupt) {
        // libtiff's error handler is process-wide: once GDAL is loaded in the same process (the
        // GdalSource tests, or `vts build` probing its first input), libtiff's "Read error at
        // scanline" goes to GDAL instead of OpenImageIO, whose read then just fails: still exit
        // 5, named "corrupt" rather than "truncated".
        expect_damaged(st, ErrorCode::corrupt, cut_path, "reading rows");
        continue;
      }
      expect_damaged(st, ErrorCode::truncated, cut_path, "reading rows");
    }
  }
}

TEST(ImageSource, TruncatedHeaderIsTruncatedNotUnreadable) {
  TempDir dir;
  write_image(dir / "a.png");
  write_image(dir / "a.jpg");
  write_image(dir / "a.tif");
  for (const auto& [name, keep] : std::vector<std::pair<std::string, std::size_t>>{
           {"a.png", 40}, {"a.jpg", 300}, {"a.tif", 60}}) {
    const fs::path cut_path = dir / ("head-" + name);
    spit(cut_path, slurp(dir / name).substr(0, keep));
    Status st = read_all({cut_path});
    ASSERT_FALSE(st.ok()) << name;
    EXPECT_TRUE(st.error().code == ErrorCode::truncated || st.error().code == ErrorCode::corrupt)
        << st.error().message;
    EXPECT_EQ(exit_code(st.error().code), 5) << st.error().message;
    EXPECT_NE(st.error().message.find(cut_path.string()), std::string::npos) << st.error().message;
    EXPECT_NE(st.error().message.find("opening it as"), std::string::npos) << st.error().message;
  }
  spit(dir / "empty.png", "");
  expect_damaged(read_all({dir / "empty.png"}), ErrorCode::truncated, dir / "empty.png", "empty");
  // Not an image at all: a wrong argument, not a damaged image.
  spit(dir / "text.png", "this is not an image\n");
  Status st = read_all({dir / "text.png"});
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, ErrorCode::invalid_argument) << st.error().message;
}

TEST(ImageSource, PngWithAFlippedDataByteFailsItsCrc) {
  TempDir dir;
  write_image(dir / "a.png");
  std::string bytes = slurp(dir / "a.png");
  bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x55);
  spit(dir / "flip.png", bytes);
  expect_damaged(read_all({dir / "flip.png"}), ErrorCode::corrupt, dir / "flip.png", "CRC error");
}

TEST(ImageSource, MosaicWithATruncatedSecondPieceFailsNamingThatPiece) {
  TempDir dir;
  write_image(dir / "a.png");
  const std::string bytes = slurp(dir / "a.png");
  spit(dir / "b.png", bytes.substr(0, bytes.size() * 3 / 4));
  expect_damaged(read_all({dir / "a.png", dir / "b.png"}, 2), ErrorCode::truncated, dir / "b.png",
                 "reading rows");
}

TEST(ImageSource, HarmlessOdditiesStillRead) {
  TempDir dir;
  write_image(dir / "a.jpg");
  write_image(dir / "a.png");
  // Bytes after the JPEG's EOI or the PNG's IEND: never read by the decoder.
  spit(dir / "trailing.jpg", slurp(dir / "a.jpg") + "trailing garbage after EOI\n");
  spit(dir / "trailing.png", slurp(dir / "a.png") + "trailing garbage after IEND\n");
  EXPECT_TRUE(read_all({dir / "trailing.jpg"}).ok());
  EXPECT_TRUE(read_all({dir / "trailing.png"}).ok());
  // A JFIF revision libjpeg does not know: a warning at open, the pixels are intact.
  std::string jfif = slurp(dir / "a.jpg");
  ASSERT_EQ(jfif.substr(6, 5), std::string("JFIF\0", 5));
  jfif[11] = 3;
  spit(dir / "jfif3.jpg", jfif);
  EXPECT_TRUE(read_all({dir / "jfif3.jpg"}).ok());
}

TEST(ImageSource, CheckReadTakesDecoderMessagesOnSuccessfulReadsAsDamage) {
  const fs::path f = "x.tif";
  EXPECT_TRUE(detail::check_read(f, "reading rows 0..16", true, "").ok());
  // libtiff's short strip: read_scanlines() returns true with this message.
  expect_damaged(
      detail::check_read(f, "reading rows 0..16", true,
                         "TIFFReadEncodedStrip failed reading line y=0,z=0: Read error at "
                         "scanline 4294967295; got 10 bytes, expected 98304\n"),
      ErrorCode::truncated, f, "reading rows 0..16 failed: TIFFReadEncodedStrip");
  expect_damaged(detail::check_read(f, "reading rows 0..16", false, ""), ErrorCode::corrupt, f,
                 "reading rows 0..16 failed");
  // libjpeg's metadata warnings (jerror.h's texts, as OpenImageIO passes them on).
  for (const char* warning : {"JPEG error: Warning: unknown JFIF revision number 3.01 (\"x\")\n",
                              "JPEG error: Invalid SOS parameters for sequential JPEG (\"x\")\n",
                              "JPEG error: Unknown Adobe color transform code 3 (\"x\")\n"})
    EXPECT_TRUE(detail::check_read(f, "opening it", true, warning).ok()) << warning;
  // A harmless warning next to damage is still damage; repeats are said once.
  Status st = detail::check_read(f, "reading rows 0..16", true,
                                 "Warning: unknown JFIF revision number 3.01\n"
                                 "Corrupt JPEG data: bad Huffman code\n"
                                 "Corrupt JPEG data: bad Huffman code\n");
  expect_damaged(st, ErrorCode::corrupt, f, "failed: Corrupt JPEG data: bad Huffman code");
  EXPECT_EQ(st.error().message.find("JFIF"), std::string::npos) << st.error().message;
  EXPECT_EQ(st.error().message.find("code; Corrupt"), std::string::npos) << st.error().message;
}

TEST(ImageSource, ReadRgba8RefusesATruncatedJpeg) {
  TempDir dir;
  write_image(dir / "a.jpg");
  const std::string bytes = slurp(dir / "a.jpg");
  spit(dir / "cut.jpg", bytes.substr(0, bytes.size() / 2));
  auto img = read_rgba8(dir / "cut.jpg");
  ASSERT_FALSE(img.ok()) << "a truncated JPEG read as an image";
  EXPECT_EQ(img.error().code, ErrorCode::truncated) << img.error().message;
  EXPECT_TRUE(read_rgba8(dir / "a.jpg").ok());
}

}  // namespace
}  // namespace vts

namespace vts {
namespace {

// A window of columns reads exactly those columns of the whole rows, for scanline and tiled files
// and across the pieces of a mosaic (a shard reads only its window).
TEST(ImageSource, AWindowOfColumnsIsThoseColumnsOfTheWholeRows) {
  TempDir dir;
  write_image(dir / "a.png");
  write_image(dir / "t.tif", "tiled");
  for (const std::vector<fs::path>& inputs :
       {std::vector<fs::path>{dir / "a.png"}, std::vector<fs::path>{dir / "t.tif"},
        std::vector<fs::path>{dir / "a.png", dir / "t.tif", dir / "a.png"}}) {
    auto whole = ImageSource::open(inputs, static_cast<std::uint32_t>(inputs.size()), 1).value();
    auto part = ImageSource::open(inputs, static_cast<std::uint32_t>(inputs.size()), 1).value();
    const std::uint64_t W = whole->width();
    std::vector<std::uint8_t> rows(W * 4 * 40), window;
    // Windows inside one tile, across tile edges, and across pieces; rows across tile rows.
    for (auto [x0, x1, y] : {std::tuple<std::uint64_t, std::uint64_t, std::uint64_t>{3, 50, 0},
                             {60, 200, 50},
                             {500, 530, 100},
                             {0, W, 300},
                             {W - 70, W, 460}}) {
      SCOPED_TRACE(inputs.size());
      x1 = std::min(x1, W);  // 500..530 crosses pieces in the mosaic
      ASSERT_TRUE(whole->read_rows(y, 40, rows.data()));
      window.assign((x1 - x0) * 4 * 40, 0);
      const Status st = part->read_window(x0, x1, y, 40, window.data());
      ASSERT_TRUE(st) << st.error().message << " columns " << x0 << ".." << x1;
      for (std::uint64_t r = 0; r < 40; ++r)
        ASSERT_EQ(0, std::memcmp(window.data() + r * (x1 - x0) * 4, rows.data() + (r * W + x0) * 4,
                                 (x1 - x0) * 4))
            << "row " << y + r << " columns " << x0 << ".." << x1;
    }
  }
}

}  // namespace
}  // namespace vts
