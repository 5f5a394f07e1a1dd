#include "vts/base/file_io.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
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

// ---- open_input_file: only regular files are inputs ---------------------------------------------

TEST(FileIo, ARegularFileOpensAndReadsWhole) {
  const vts::test::TempDir dir("vts-file-io");
  touch(dir / "in.json");
  struct stat st {};
  auto fd = vts::open_input_file(dir / "in.json", &st);
  ASSERT_TRUE(fd.ok()) << fd.error().message;
  EXPECT_EQ(st.st_size, 5);
  ::close(*fd);
  EXPECT_TRUE(vts::check_input_file(dir / "in.json").ok());
  EXPECT_EQ(vts::read_file(dir / "in.json").value(), "bytes");
}

TEST(FileIo, AMissingInputIsNotFoundNamingIt) {
  const vts::test::TempDir dir("vts-file-io");
  auto fd = vts::open_input_file(dir / "missing.png");
  ASSERT_FALSE(fd.ok());
  EXPECT_EQ(fd.error().code, vts::ErrorCode::not_found);
  EXPECT_NE(fd.error().message.find("missing.png"), std::string::npos) << fd.error().message;
}

// A FIFO without a writer would block a plain open() forever, /dev/zero never ends: both are
// refused before a byte is read, as are folders, naming the file and its kind.
TEST(FileIo, AFifoADeviceOrAFolderIsRefusedAtOnceNamingTheFileAndItsKind) {
  const vts::test::TempDir dir("vts-file-io");
  const fs::path fifo = dir / "fifo.pmtiles";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::vector<std::pair<fs::path, std::string>> cases = {
      {fifo, "(FIFO)"}, {"/dev/zero", "(character device)"}, {dir.path(), "(directory)"}};
  for (const auto& [path, kind] : cases) {
    SCOPED_TRACE(path.string());
    const auto t0 = std::chrono::steady_clock::now();
    for (const vts::Error& e :
         {vts::open_input_file(path).error(), vts::check_input_file(path).error(),
          vts::read_file(path).error()}) {
      EXPECT_EQ(e.code, vts::ErrorCode::invalid_argument);
      EXPECT_EQ(e.message, "not a regular file: " + path.string() + " " + kind);
    }
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  }
}

// A name, whatever bytes it holds, stays one line and cannot drive a terminal: control bytes (a
// newline that would forge a line, ESC) and UTF-8-encoded C1 controls become \xHH; text, UTF-8
// and backslashes pass as they are, so escaping twice changes nothing.
// Every file in `dir`, by name.
std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

TEST(FileIo, AnAtomicWriteReplacesTheFileWholeAndAFailedOneLeavesTheOldOne) {
  const vts::test::TempDir dir("vts-file-io");
  const fs::path p = dir / "config.json";
  ASSERT_TRUE(vts::write_file_atomically(p, "first").ok());
  EXPECT_EQ(vts::read_file(p).value(), "first");
  // Piece by piece, through the descriptor it is given.
  vts::Status st = vts::write_file_atomically(p, [](int fd, const fs::path&) -> vts::Status {
    for (const char* piece : {"sec", "ond"})
      if (::write(fd, piece, 3) != 3) return vts::make_error(vts::ErrorCode::io, "short");
    return {};
  });
  ASSERT_TRUE(st.ok()) << st.error().to_string();
  EXPECT_EQ(vts::read_file(p).value(), "second");
  // A writer's error is the error; the old file stays, no temporary is left.
  st = vts::write_file_atomically(p, [](int fd, const fs::path& tmp) -> vts::Status {
    EXPECT_EQ(::write(fd, "third", 5), 5);
    return vts::make_error(vts::ErrorCode::corrupt, "gave up on " + tmp.string());
  });
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, vts::ErrorCode::corrupt);
  EXPECT_EQ(vts::read_file(p).value(), "second");
  EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"config.json"});
  // A folder that does not exist: io, naming the temporary's place.
  st = vts::write_file_atomically(dir / "none" / "x.json", "x");
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, vts::ErrorCode::io);
  EXPECT_NE(st.error().message.find("none"), std::string::npos) << st.error().message;
}

TEST(EscapeControls, ControlBytesAndC1ControlsBecomeHexAndEverythingElsePasses) {
  EXPECT_EQ(vts::escape_controls(""), "");
  EXPECT_EQ(vts::escape_controls("plain/name-1.pmtiles"), "plain/name-1.pmtiles");
  EXPECT_EQ(vts::escape_controls("a\nb\rc\td"), "a\\x0ab\\x0dc\\x09d");
  EXPECT_EQ(vts::escape_controls("x\nvts serve: forged"), "x\\x0avts serve: forged");
  EXPECT_EQ(vts::escape_controls("\x1b[31mred\x1b[0m"), "\\x1b[31mred\\x1b[0m");
  EXPECT_EQ(vts::escape_controls(std::string_view("a\0b\x7f", 4)), "a\\x00b\\x7f");
  EXPECT_EQ(vts::escape_controls("\xC2\x9B"
                                 "2J \xC2\x85"),
            "\\xc2\\x9b"
            "2J \\xc2\\x85");
  EXPECT_EQ(vts::escape_controls("caf\xC3\xA9 \xC2\xA0 \xE2\x80\x94 \xFF \\x41"),
            "caf\xC3\xA9 \xC2\xA0 \xE2\x80\x94 \xFF \\x41");
  EXPECT_EQ(vts::escape_controls("\xC2"), "\xC2");  // a lone lead byte at the end
  for (std::string_view once : {"\x1b\n", "\xC2\x9B", "\xC2\n"}) {
    const std::string escaped = vts::escape_controls(once);
    EXPECT_EQ(vts::escape_controls(escaped), escaped);
    for (const char c : escaped) EXPECT_FALSE(static_cast<unsigned char>(c) < 0x20);
  }
}

// The five markup characters become character references, wherever they stand; every other
// byte (text, UTF-8, even bytes that are not UTF-8) passes as it is.
TEST(HtmlEscape, TheFiveMarkupCharactersBecomeReferencesAndNothingElseChanges) {
  EXPECT_EQ(vts::html_escape(""), "");
  EXPECT_EQ(vts::html_escape("plain text 123"), "plain text 123");
  EXPECT_EQ(vts::html_escape("a<b>&\"c'd"), "a&lt;b&gt;&amp;&quot;c&#39;d");
  EXPECT_EQ(vts::html_escape("&amp;"), "&amp;amp;");  // escaped text is escaped again
  EXPECT_EQ(vts::html_escape("<<>>"), "&lt;&lt;&gt;&gt;");
  EXPECT_EQ(vts::html_escape("caf\xC3\xA9 \xE2\x80\x94 \xFF"), "caf\xC3\xA9 \xE2\x80\x94 \xFF");
  EXPECT_EQ(vts::html_escape(std::string_view("a\0b", 3)), std::string("a\0b", 3));
}

}  // namespace

TEST(HttpText, IcontainsFindsAPartInAnyAsciiCase) {
  EXPECT_TRUE(vts::icontains("Image/WebP,*/*;q=0.8", "image/"));
  EXPECT_TRUE(vts::icontains("text/HTML", "text/html"));
  EXPECT_TRUE(vts::icontains("abc", ""));
  EXPECT_TRUE(vts::icontains("abc", "abc"));
  EXPECT_FALSE(vts::icontains("*/*", "image/"));
  EXPECT_FALSE(vts::icontains("ab", "abc"));
  EXPECT_FALSE(vts::icontains("", "a"));
}
