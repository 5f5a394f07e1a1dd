// The GPU side of sparse virtual texturing and its per-frame loop (docs/RENDERER.md, "The
// pipeline"). One VirtualTexture draws one tiled image (a vts::Geometry) on a scene; it owns the
// physical texture (a slot atlas in the tiles' format: SRGB8_ALPHA8 for rgba8, S3TC DXT1 for bc1),
// the page table (an R32UI array texture, kMaxLevels layers of W x W), the feedback pass and its
// fenced readback ring, the upload ring, and the CPU core (FeedbackProcessor, TileStream,
// MipBiasController). render() runs one frame into the texture's own framebuffer.
//
// Thread safety: GL-thread only; create, use and destroy it with its GlContext current.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/feedback.hpp"
#include "vts/renderer/mip_bias.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/tile_stream.hpp"

namespace vts::renderer {

enum class DebugView : std::uint8_t {
  none = 0,
  levels,      // tint by the level actually sampled (red = coarse ... blue = fine)
  physical,    // the physical texture (slot atlas), stretched over the screen
  page_table,  // the page-table layer of the level at the screen centre, one colour per slot
};

struct VirtualTextureOptions {
  // Physical slots, the root's included: 2 to kMaxSlots (a 1024 x 1024 grid of slots, beyond any
  // GL's largest texture; create() checks the GL's own limit).
  static constexpr std::uint32_t kMaxSlots = 1u << 20;
  std::uint32_t slots = 256;
  std::uint32_t window = 64;  // page-table window W per level (power of two)
  int feedback_divisor = 8;   // k: the feedback pass renders at 1/k resolution (1, 2, 4, 8, 16)
  int readback_ring = 3;      // feedback frames in flight (>= 1)
  std::uint32_t upload_tiles = 32;         // per-frame upload budget: tiles ...
  std::uint64_t upload_bytes = 16u << 20;  // ... and bytes
  std::uint32_t keep_frames = 8;           // a tile unseen for fewer frames is never evicted
  bool trilinear = true;                   // false: bilinear at the nearest finer level only
  // Anisotropic filtering: up to this many trilinear taps along the footprint's major axis, each
  // through its own page-table lookup (so no slot border limits it); 1 = isotropic. The level is
  // chosen from max(major / taps, minor), as hardware anisotropic filtering does.
  int anisotropy = 1;
  double max_bias = 4.0;  // upper bound of the automatic mip bias
  DebugView debug = DebugView::none;
  // Every decision of the tile stream (requests, cancellations, placements, evictions, absences,
  // failures), in order, on the render thread: the load tester's simulated viewers make the same.
  std::function<void(const StreamEvent&)> trace;
};

// What one frame did; the viewer's HUD and `vts view --json` print these.
struct FrameStats {
  std::uint64_t frame = 0;
  double vt_cpu_ms = 0;      // CPU time in the virtual-texturing system (feedback, table, uploads)
  double frame_ms = 0;       // the whole render() call, GL submission included
  std::uint32_t wanted = 0;  // distinct tiles the latest feedback asked for (ancestors included)
  std::uint32_t wanted_missing = 0;  // of those, not resident
  std::uint32_t resident = 0;        // tiles in the physical texture
  std::uint32_t pending = 0;         // tiles asked of the client and not delivered yet
  std::uint32_t uploads = 0;         // tiles uploaded this frame
  std::uint64_t upload_bytes = 0;
  std::uint32_t feedback_frames = 0;  // feedback buffers processed this frame (0 or 1)
  double mip_bias = 0;
  double hit_ratio = 0;  // wanted tiles already resident / wanted (1 when nothing wanted)
  std::uint64_t evictions = 0, refusals = 0;  // cumulative slot-cache counters
  std::uint64_t absent = 0, errors = 0;       // cumulative: tiles the source lacks / failed
  // The feedback of the current view (not an older one still in the readback ring) has been read
  // and every tile it wants is resident: the frame is at full resolution (at the current bias).
  bool complete = false;
};

class VirtualTexture {
 public:
  // Needs a current GL 4.5 core context. Errors: options out of range, a physical texture larger
  // than GL_MAX_TEXTURE_SIZE, a geometry with more than kMaxLevels levels, shader build failures
  // (with the driver's log); for a bc1 tileset, a GL without GL_EXT_texture_compression_s3tc and
  // GL_EXT_texture_sRGB, or a stored tile size T + 2B that is not a multiple of 4 (unsupported).
  // A decoded tile not of the tileset's format and stored size is dropped and counted in
  // FrameStats::errors.
  static Result<std::unique_ptr<VirtualTexture>> create(std::shared_ptr<client::TileClient> client,
                                                        const Geometry& geometry,
                                                        VirtualTextureOptions options = {});
  ~VirtualTexture();
  VirtualTexture(const VirtualTexture&) = delete;
  VirtualTexture& operator=(const VirtualTexture&) = delete;

  // Renders one frame of `scene` at width x height into the texture's own framebuffer. A scene's
  // shader variant is compiled the first time it is drawn; if that fails the frame is empty,
  // counted in FrameStats::errors, and the driver's log is in last_error().
  FrameStats render(const Scene& scene, int width, int height);
  FrameStats render(const PlaneView& view, int width, int height);  // a PlaneScene
  std::optional<Error> last_error() const;
  // The latest tile that could not be shown (the client's error, or a tile of the wrong size or
  // format), naming it; it is retried with back-off and counted in FrameStats::errors.
  std::optional<Error> last_tile_error() const;
  // The last frame, sRGB RGBA8, rows top to bottom (a blocking read: screenshots and tests).
  Image read_image() const;
  // Copies the last frame to the window's default framebuffer (0), scaled to width x height.
  void blit_to_screen(int width, int height) const;

  // The tiles the latest processed feedback frame asked for (ancestors included, coarse first), as
  // they were requested: what the load test's demand simulator is checked against.
  const std::vector<TileRequest>& last_wanted() const;
  // The mip bias in effect (what the latest feedback was reduced with).
  double mip_bias() const;

  void set_debug_view(DebugView view);
  DebugView debug_view() const;
  const Geometry& geometry() const;
  const VirtualTextureOptions& options() const;
  // GPU memory of the page-table texture (whatever the image size) and of the slot atlas, from
  // the textures' sizes as GL reports them (for bc1, GL_TEXTURE_COMPRESSED_IMAGE_SIZE: half a
  // byte per texel, an eighth of the rgba8 atlas of the same slots).
  std::uint64_t page_table_gpu_bytes() const;
  std::uint64_t physical_gpu_bytes() const;
  // The format of the tiles and of the physical texture: rgba8, or bc1 for a bc1 tileset.
  PixelFormat tile_format() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
  explicit VirtualTexture(std::unique_ptr<Impl> impl);
};

}  // namespace vts::renderer
