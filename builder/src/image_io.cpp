#include "vts/builder/image_io.hpp"

#include <OpenImageIO/imageio.h>

#include <string>

#include "image_source.hpp"
#include "vts/base/file_io.hpp"

namespace vts {
inline namespace builder {

namespace OIIO = OIIO_NAMESPACE;

namespace {

std::string quoted(const std::filesystem::path& p) {
  return "'" + p.string() + "'";
}

}  // namespace

Result<Rgba8Image> read_rgba8(const std::filesystem::path& path) {
  // Not a FIFO or a device: OpenImageIO would wait for a writer, or read /dev/zero forever.
  if (Status s = check_input_file(path); !s) {
    if (s.error().code == ErrorCode::not_found)
      return make_error(ErrorCode::not_found, "cannot read " + quoted(path) + ": no such file");
    return s.error();
  }
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);  // keep straight alpha: no premultiplying
  auto in = OIIO::ImageInput::open(path.string(), &config);
  if (!in)
    return make_error(ErrorCode::corrupt, "cannot read " + quoted(path) + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  const int channels = spec.nchannels;
  if (spec.width <= 0 || spec.height <= 0 || spec.width > (1 << 15) || spec.height > (1 << 15) ||
      channels < 1 || channels > 4)
    return make_error(ErrorCode::unsupported, "cannot read " + quoted(path) + ": " +
                                                  std::to_string(spec.width) + "x" +
                                                  std::to_string(spec.height) + " with " +
                                                  std::to_string(channels) + " channels");
  std::vector<std::uint8_t> raw(std::size_t(spec.width) * spec.height * channels);
  // Decoders report damage in the middle of the pixels on a read that still succeeds.
  const bool ok = in->read_image(0, 0, 0, channels, OIIO::TypeDesc::UINT8, raw.data());
  if (Status st = detail::check_read(path, "reading its pixels", ok, in->geterror()); !st)
    return st.error();
  in->close();
  Rgba8Image img{spec.width, spec.height,
                 std::vector<std::uint8_t>(std::size_t(spec.width) * spec.height * 4)};
  const std::size_t n = std::size_t(spec.width) * spec.height;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* s = raw.data() + i * channels;
    std::uint8_t* d = img.rgba.data() + i * 4;
    if (channels <= 2) {
      d[0] = d[1] = d[2] = s[0];
      d[3] = channels == 2 ? s[1] : 255;
    } else {
      d[0] = s[0];
      d[1] = s[1];
      d[2] = s[2];
      d[3] = channels == 4 ? s[3] : 255;
    }
  }
  return img;
}

}  // namespace builder
}  // namespace vts
