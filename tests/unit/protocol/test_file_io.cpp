#include "vts/protocol/file_io.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <vector>

#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;

namespace {

void touch(const fs::path& p) {
  std::ofstream(p) << "bytes";
}

TEST(FileIo, AnOutputThatIsAnInputByAnyPathIsRefusedNamingBoth) {
  const vts::test::TempDir dir("vts-file-io");
  const fs::path in = dir / "in.jpg", other = dir / "other.jpg";
  touch(in);
  touch(other);
  fs::create_symlink(in, dir / "link.pmtiles");
  fs::create_hard_link(in, dir / "hard.pmtiles");
  fs::create_directories(dir / "sub");
  const std::vector<fs::path> inputs = {other, in};
  for (const fs::path& out : {in, dir / "link.pmtiles", dir / "hard.pmtiles", dir / "." / "in.jpg",
                              dir / "sub" / ".." / "in.jpg"}) {
    SCOPED_TRACE(out.string());
    vts::Status s = vts::check_output_is_not_an_input(out, inputs);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, vts::ErrorCode::invalid_argument);
    EXPECT_NE(s.error().message.find(out.string()), std::string::npos) << s.error().message;
    EXPECT_NE(s.error().message.find(in.string()), std::string::npos) << s.error().message;
  }
}

TEST(FileIo, ANewOrDifferentOutputIsAccepted) {
  const vts::test::TempDir dir("vts-file-io");
  const fs::path in = dir / "in.jpg", existing = dir / "old.pmtiles";
  touch(in);
  touch(existing);
  const std::vector<fs::path> inputs = {in};
  EXPECT_TRUE(vts::check_output_is_not_an_input(dir / "new.pmtiles", inputs).ok());
  EXPECT_TRUE(vts::check_output_is_not_an_input(existing, inputs).ok());
  EXPECT_TRUE(vts::check_output_is_not_an_input(dir / "new.pmtiles", {}).ok());
}

}  // namespace
