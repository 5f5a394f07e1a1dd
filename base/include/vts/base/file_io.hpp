// Whole small files in and out (configs, camera paths, reports), and text helpers for the
// protocols' case-insensitive tokens, for HTML and for log lines. Not for archives or tiles: those
// stream.
#pragma once

#include <filesystem>
#include <functional>
#include <initializer_list>
#include <span>
#include <string>
#include <string_view>

#include "vts/base/result.hpp"

struct stat;

namespace vts {
inline namespace base {

// Replaces `path` with `bytes` atomically: a reader (or a crash) sees either the old file or the
// whole new one, never a part. Writes a uniquely named temporary beside `path` (created with
// O_EXCL, mode 0666 & ~umask), fsyncs it, renames it over `path`, then fsyncs the folder (best
// effort). On failure nothing but the old file is left. Error io, naming the file and the cause.
Status write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

// The same for a file written piece by piece (an archive): `write` is given the temporary file's
// descriptor (O_WRONLY, at offset 0) and name (for its messages) and writes every byte; its error
// ends the write, with the temporary removed. With `folder_sync_required` a failed fsync of the
// folder after the rename is an error too (the caller promised a durable file); otherwise it is
// best effort.
Status write_file_atomically(
    const std::filesystem::path& path,
    const std::function<Status(int fd, const std::filesystem::path& temporary)>& write,
    bool folder_sync_required = false);

// invalid_argument, naming both, when `output` already exists as one of `inputs`: the same file
// by any path, a symbolic link to it or a hard link (what a command would destroy by writing its
// output over its own input). Every command that writes a file it also reads from checks this
// before it writes anything.
Status check_output_is_not_an_input(const std::filesystem::path& output,
                                    std::span<const std::filesystem::path> inputs);

// What a command checks of a file it will write, before any long work: that `output` is not a
// folder, that the folder it goes in exists, and check_output_is_not_an_input(output, inputs).
// invalid_argument naming `option` ("--record") and the file. An empty `output` (none asked for)
// passes.
Status check_output_file(const std::filesystem::path& output, std::string_view option,
                         std::initializer_list<std::filesystem::path> inputs);

// Opens an input file for reading and returns its descriptor (O_CLOEXEC; the caller closes it),
// with its fstat in `*st` when `st` is given. Opened with O_NONBLOCK, so a FIFO never blocks the
// open() waiting for a writer; anything but a regular file (a FIFO, /dev/zero, a socket, a folder)
// is then refused, before a byte is read: invalid_argument "not a regular file: PATH (KIND)".
// Missing: not_found; any other refusal by the system: io. Every message names the file. Every
// command that reads a file it was given (images, archives, configs) opens it through here, so
// none can spin on an endless device or hang on a FIFO. O_NONBLOCK stays set on the descriptor,
// which changes nothing for a regular file.
Result<int> open_input_file(const std::filesystem::path& path, struct stat* st = nullptr);

// open_input_file() then close: for an input that a library (OpenImageIO) opens by its name.
Status check_input_file(const std::filesystem::path& path);

// The whole file, opened through open_input_file(). Error not_found (missing), invalid_argument
// (not a regular file) or io, naming the file.
Result<std::string> read_file(const std::filesystem::path& path);

// HTTP-style text: spaces and tabs (and CR/LF) trimmed from both ends; ASCII case-insensitive
// comparison, prefix test and search (no copy: these run on request headers).
std::string_view trim(std::string_view s) noexcept;
bool iequals(std::string_view a, std::string_view b) noexcept;
bool istarts_with(std::string_view s, std::string_view prefix) noexcept;
bool icontains(std::string_view s, std::string_view part) noexcept;

// Text for HTML (and SVG) element content and quoted attribute values (double or single quotes):
// & < > " ' as character references (&amp; &lt; &gt; &quot; &#39;); every other byte as it is,
// so UTF-8 is not checked here (a caller that takes untrusted bytes cleans them first).
std::string html_escape(std::string_view s);

// Text for one line of a log or of a plain-text body, whatever bytes it came from (a file name, a
// request target, an error message naming them): every control byte (below 0x20, which includes
// newline, carriage return and ESC, and 0x7f) and each byte of a UTF-8-encoded C1 control
// (U+0080..U+009F, which some terminals obey as ESC [ ...) as \xHH (lower-case hex); every other
// byte as it is, so a UTF-8 name stays readable. The result has no control bytes, so it cannot
// end a line early or move the cursor, and escaping it again changes nothing.
std::string escape_controls(std::string_view s);

}  // namespace base
}  // namespace vts
