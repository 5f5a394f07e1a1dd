// The builder's image reader (OpenImageIO) against the one PNG writer (libpng).
#include "vts/builder/image_io.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "vts/imaging/web_image.hpp"

namespace fs = std::filesystem;

namespace vts {
namespace {

TEST(ImageIo, PngRoundTripsExactlyAndErrorsNameThePath) {
  const fs::path dir = fs::temp_directory_path() / ("vts-image-io-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const int w = 13, h = 9;
  std::vector<std::uint8_t> rgba(std::size_t(w) * h * 4);
  for (std::size_t i = 0; i < rgba.size(); ++i)
    rgba[i] = static_cast<std::uint8_t>((i * 89 + 7) ^ (i >> 3));
  const fs::path p = dir / "round.png";
  Status written = imaging::write_png(p, w, h, rgba);
  ASSERT_TRUE(written.ok()) << written.error().to_string();
  auto back = read_rgba8(p);
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  EXPECT_EQ(back->width, w);
  EXPECT_EQ(back->height, h);
  EXPECT_EQ(back->rgba, rgba);

  const fs::path nowhere = dir / "no-such-dir" / "x.png";
  Status bad = imaging::write_png(nowhere, w, h, rgba);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find(nowhere.string()), std::string::npos) << bad.error().message;
  auto missing = read_rgba8(nowhere);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, ErrorCode::not_found);
  EXPECT_NE(missing.error().message.find(nowhere.string()), std::string::npos);
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace
}  // namespace vts
