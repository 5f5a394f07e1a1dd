#include "vts/renderer/virtual_texture.hpp"

#include <epoxy/gl.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "vts/renderer/feedback.hpp"
#include "vts/renderer/gl_check.hpp"
#include "vts/renderer/gl_handle.hpp"
#include "vts/renderer/gl_program.hpp"
#include "vts/renderer/gl_uniforms.hpp"
#include "vts/renderer/page_table.hpp"
#include "vts/renderer/pyramid.hpp"
#include "vts/renderer/shaders.hpp"
#include "vts/renderer/tile_stream.hpp"

namespace vts::renderer {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Waits for a fence; true once signalled (or when there is none).
bool fence_done(GLsync fence, GLuint64 timeout_ns) {
  if (!fence) return true;
  const GLenum r = glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, timeout_ns);
  return r == GL_ALREADY_SIGNALED || r == GL_CONDITION_SATISFIED;
}

void delete_fence(GLsync& fence) {
  if (fence) glDeleteSync(fence);
  fence = nullptr;
}

bool valid_divisor(int k) {
  return k == 1 || k == 2 || k == 4 || k == 8 || k == 16;
}

std::string gl_renderer() {
  const auto* name = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  return name ? name : "unknown renderer";
}

// The physical texture's internal format for the tiles' decoded format: sRGB either way, so
// filtering happens in linear light whatever the codec.
GLenum physical_format(PixelFormat format) {
  return format == PixelFormat::bc1 ? GL_COMPRESSED_SRGB_ALPHA_S3TC_DXT1_EXT : GL_SRGB8_ALPHA8;
}

// Bytes of one stored tile of side s in the upload ring and the physical texture: 4 per texel
// (rgba8), or one 8-byte block per 4 x 4 texels (bc1; s is a multiple of 4).
std::uint64_t tile_bytes(PixelFormat format, std::uint32_t s) {
  return format == PixelFormat::bc1 ? std::uint64_t(s / 4) * (s / 4) * 8 : std::uint64_t(s) * s * 4;
}

}  // namespace

class VirtualTexture::Impl {
 public:
  Impl(std::shared_ptr<client::TileClient> client, const Geometry& geometry, PixelFormat format,
       Pyramid pyramid, ClipmapPageTable table, VirtualTextureOptions options)
      : client_(std::move(client)),
        geometry_(geometry),
        format_(format),
        pyramid_(pyramid),
        table_(std::move(table)),
        stream_(TileStreamOptions{.slots = {options.slots, options.keep_frames},
                                  .max_bias = options.max_bias,
                                  .trace = options.trace}),
        feedback_(pyramid),
        options_(options) {}

  ~Impl() {
    for (auto& r : readbacks_) delete_fence(r.fence);
    for (auto& u : uploads_) delete_fence(u.fence);
    // The GL objects are the members' handles.
  }

  Status init() {
    // The plane's programs are built now so that a broken driver fails here, not at a frame.
    if (auto p = programs_for(PlaneScene(PlaneView{})); !p) return p.error();
    auto dbg = link_program(detail::kFullscreenVertex, detail::kDebugFragment, "debug view");
    if (!dbg) return dbg.error();
    debug_prog_ = std::move(*dbg);
    glCreateVertexArrays(1, vao_.out());

    // Page table: kMaxLevels layers of W x W, R32UI, all zero (invalid).
    const GLsizei w = GLsizei(table_.window());
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, page_tex_.out());
    glTextureStorage3D(page_tex_.get(), 1, GL_R32UI, w, w, kMaxLevels);
    glTextureParameteri(page_tex_.get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(page_tex_.get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    const GLuint zero = 0;
    glClearTexImage(page_tex_.get(), 0, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);

    // Physical texture: a grid of slots_per_row_ x rows slots of (T + 2B)^2 texels.
    slot_size_ = geometry_.stored_size();
    slots_per_row_ = std::uint32_t(std::ceil(std::sqrt(double(options_.slots))));
    const std::uint32_t rows = (options_.slots + slots_per_row_ - 1) / slots_per_row_;
    atlas_w_ = slots_per_row_ * slot_size_;
    atlas_h_ = rows * slot_size_;
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    if (atlas_w_ > std::uint32_t(max_size) || atlas_h_ > std::uint32_t(max_size)) {
      return Error{ErrorCode::invalid_argument,
                   std::to_string(options_.slots) + " slots of " + std::to_string(slot_size_) +
                       " texels need a " + std::to_string(atlas_w_) + " x " +
                       std::to_string(atlas_h_) + " physical texture, above this GL's " +
                       "GL_MAX_TEXTURE_SIZE of " + std::to_string(max_size)};
    }
    glCreateTextures(GL_TEXTURE_2D, 1, physical_tex_.out());
    glTextureStorage2D(physical_tex_.get(), 1, physical_format(format_), GLsizei(atlas_w_),
                       GLsizei(atlas_h_));
    glTextureParameteri(physical_tex_.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTextureParameteri(physical_tex_.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTextureParameteri(physical_tex_.get(), GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTextureParameteri(physical_tex_.get(), GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    if (format_ == PixelFormat::bc1) {
      clear_compressed_atlas();
    } else {
      const std::uint8_t black[4] = {0, 0, 0, 255};
      glClearTexImage(physical_tex_.get(), 0, GL_RGBA, GL_UNSIGNED_BYTE, black);
    }

    // Upload ring: pixel-unpack buffers of the per-frame byte budget each.
    tile_bytes_ = tile_bytes(format_, slot_size_);
    if (options_.upload_bytes < tile_bytes_) {
      return Error{ErrorCode::invalid_argument, "the upload budget of " +
                                                    std::to_string(options_.upload_bytes) +
                                                    " bytes per frame is below one tile (" +
                                                    std::to_string(tile_bytes_) + " bytes)"};
    }
    uploads_.resize(3);
    for (auto& u : uploads_) {
      glCreateBuffers(1, u.buffer.out());
      glNamedBufferStorage(u.buffer.get(), GLsizeiptr(options_.upload_bytes), nullptr,
                           GL_MAP_WRITE_BIT);
    }
    readbacks_.resize(std::size_t(options_.readback_ring));
    glCreateFramebuffers(1, color_fbo_.out());
    glCreateFramebuffers(1, feedback_fbo_.out());

    // The root first: everything falls back on it.
    issue(stream_.start());
    return Status{};
  }

  // glClearTexImage does not take compressed textures: the bc1 atlas is filled with opaque black
  // blocks instead (8 zero bytes: both endpoints black, every index 0), in strips of whole block
  // rows of at most ~4 MiB from one zeroed host buffer, before any tile is uploaded.
  void clear_compressed_atlas() {
    const std::uint64_t row_bytes = std::uint64_t(atlas_w_ / 4) * 8;  // one row of blocks
    const std::uint32_t block_rows = atlas_h_ / 4;
    const std::uint32_t strip = std::uint32_t(
        std::clamp<std::uint64_t>((4u << 20) / row_bytes, 1, std::uint64_t(block_rows)));
    const std::vector<std::uint8_t> zeros(std::size_t(row_bytes * strip), 0);
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
    for (std::uint32_t r = 0; r < block_rows; r += strip) {
      const std::uint32_t n = std::min(strip, block_rows - r);
      glCompressedTextureSubImage2D(physical_tex_.get(), 0, 0, GLint(r * 4), GLsizei(atlas_w_),
                                    GLsizei(n * 4), physical_format(format_),
                                    GLsizei(row_bytes * n), zeros.data());
    }
  }

  // The colour and feedback programs of a scene's shader variant, built on first use.
  struct Programs {
    GlProgram color_program, feedback_program;
    GlProgramUniforms color, feedback;  // the programs' uniform locations
  };
  Result<Programs*> programs_for(const Scene& scene) {
    const std::string glsl = scene.glsl();
    if (auto it = programs_.find(glsl); it != programs_.end()) return &it->second;
    const std::string head = std::string("#version 450 core\n") +
                             (options_.anisotropy > 1 ? "#define ANISOTROPIC\n" : "");
    const std::string body = "uniform vec2 u_viewport;\n" + glsl + detail::kVirtualTextureFragment;
    const std::string name(scene.name());
    auto color = link_program(detail::kFullscreenVertex, head + body, (name + " colour").c_str());
    if (!color) return color.error();
    auto fb = link_program(detail::kFullscreenVertex, head + "#define FEEDBACK\n" + body,
                           (name + " feedback").c_str());
    if (!fb) return fb.error();
    const unsigned c = color->get(), f = fb->get();
    Programs p{std::move(*color), std::move(*fb), GlProgramUniforms(c), GlProgramUniforms(f)};
    return &programs_.emplace(glsl, std::move(p)).first->second;
  }

  FrameStats render(const Scene& scene, int width, int height) {
    const auto t_frame = Clock::now();
    FrameStats st;
    st.frame = ++frame_;
    resize(std::max(width, 1), std::max(height, 1));
    auto programs = programs_for(scene);
    if (!programs) {
      last_error_ = programs.error();
      ++error_count_;
      return st;
    }

    note_view(scene);
    const auto t_vt = Clock::now();
    std::vector<TileRequest> fresh;
    st.feedback_frames = collect_feedback(fresh);
    issue(stream_.frame(frame_, Clock::now(), st.feedback_frames ? &fresh : nullptr));
    st.uploads = upload_tiles(st.upload_bytes);
    recenter(scene.focus());
    upload_page_table();
    st.vt_cpu_ms = ms_since(t_vt);

    // The anchor: an integer texel near the view, so every float the GPU sees is small.
    const auto anchor = scene.anchor();
    const auto set_common = [&](GlProgramUniforms& u, int vw, int vh, float level_offset) {
      scene.set_uniforms(u, width_, height_);  // the camera is the full view's in every pass
      u.set("u_viewport", float(vw), float(vh));
      u.set_int("u_anchor", int(anchor[0]), int(anchor[1]));
      u.set("u_period", float(scene.u_period()));
      u.set_int("u_image", int(geometry_.width()), int(geometry_.height()));
      u.set_int("u_max_level", geometry_.max_zoom());
      u.set_int("u_tile_shift", std::countr_zero(geometry_.tile_size()));
      u.set("u_level_offset", level_offset);
      u.set_int("u_max_aniso", options_.anisotropy);
    };

    glBindVertexArray(vao_.get());
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);

    // Feedback pass at 1/k, read back later through the ring.
    if (!readbacks_[ring_pos_].fence) {
      set_common((*programs)->feedback, fb_w_, fb_h_, float(std::log2(double(width_) / fb_w_)));
      glBindFramebuffer(GL_FRAMEBUFFER, feedback_fbo_.get());
      glViewport(0, 0, fb_w_, fb_h_);
      glDisable(GL_FRAMEBUFFER_SRGB);
      glUseProgram(programs.value()->feedback.program());
      glDrawArrays(GL_TRIANGLES, 0, 3);
      auto& rb = readbacks_[ring_pos_];
      glBindBuffer(GL_PIXEL_PACK_BUFFER, rb.buffer.get());
      glPixelStorei(GL_PACK_ALIGNMENT, 4);
      glReadPixels(0, 0, fb_w_, fb_h_, GL_RG_INTEGER, GL_UNSIGNED_INT, nullptr);
      glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
      rb.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
      rb.view_generation = view_generation_;
      ring_pos_ = (ring_pos_ + 1) % readbacks_.size();
    }

    // Colour pass.
    glBindFramebuffer(GL_FRAMEBUFFER, color_fbo_.get());
    glViewport(0, 0, width_, height_);
    glEnable(GL_FRAMEBUFFER_SRGB);
    if (options_.debug == DebugView::physical || options_.debug == DebugView::page_table) {
      const GLuint p = debug_prog_.get();
      glProgramUniform1i(p, glGetUniformLocation(p, "u_mode"), int(options_.debug));
      const int centre_level =
          std::clamp(int(std::lround(geometry_.max_zoom() -
                                     std::log2(std::max(scene.texels_per_pixel(), 1e-9)))),
                     0, geometry_.max_zoom());
      glProgramUniform1i(p, glGetUniformLocation(p, "u_layer"), centre_level);
      glProgramUniform2f(p, glGetUniformLocation(p, "u_viewport"), float(width_), float(height_));
      glProgramUniform1i(p, glGetUniformLocation(p, "u_physical"), 0);
      glProgramUniform1i(p, glGetUniformLocation(p, "u_page_table"), 1);
      glUseProgram(p);
    } else {
      GlProgramUniforms& u = (*programs)->color;
      set_common(u, width_, height_, float(-stream_.bias()));
      std::uint32_t origins[2 * kMaxLevels];
      for (int z = 0; z < kMaxLevels; ++z) {
        origins[2 * z] = table_.origin_x(z);
        origins[2 * z + 1] = table_.origin_y(z);
      }
      glProgramUniform2uiv(u.program(), u.location("u_origin"), kMaxLevels, origins);
      u.set_uint("u_window", table_.window());
      u.set_int("u_slots_per_row", int(slots_per_row_));
      u.set("u_slot_size", float(slot_size_));
      u.set("u_border", float(geometry_.border()));
      u.set("u_atlas_inv", 1.0f / float(atlas_w_), 1.0f / float(atlas_h_));
      u.set_int("u_trilinear", options_.trilinear ? 1 : 0);
      u.set_int("u_debug", options_.debug == DebugView::levels ? 1 : 0);
      u.set_int("u_physical", 0);
      u.set_int("u_page_table", 1);
      glUseProgram(u.program());
    }
    glBindTextureUnit(0, physical_tex_.get());
    glBindTextureUnit(1, page_tex_.get());
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glDisable(GL_FRAMEBUFFER_SRGB);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);

    fill_stats(st);
    st.frame_ms = ms_since(t_frame);
    return st;
  }

  Image read_image() const {
    Image img;
    img.width = width_;
    img.height = height_;
    const std::size_t row = std::size_t(width_) * 4;
    std::vector<std::uint8_t> raw(row * std::size_t(height_));
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTextureImage(color_tex_.get(), 0, GL_RGBA, GL_UNSIGNED_BYTE, GLsizei(raw.size()),
                      raw.data());
    img.rgba.resize(raw.size());
    for (int y = 0; y < height_; ++y) {  // GL rows go bottom to top
      std::memcpy(img.rgba.data() + std::size_t(y) * row,
                  raw.data() + std::size_t(height_ - 1 - y) * row, row);
    }
    return img;
  }

  // What went wrong with a tile event that cannot be placed, naming the tile: the client's error,
  // or a decoded tile that is not the size or format of the tileset's slots.
  Error tile_error(const client::TileEvent& e) const {
    if (e.kind != client::TileEvent::Kind::decoded && e.error) {
      return make_error(e.error->code, "tile " + e.id.to_string() + ": " + e.error->message);
    }
    return make_error(ErrorCode::corrupt,
                      "tile " + e.id.to_string() + " decoded to " + std::to_string(e.image.width) +
                          "x" + std::to_string(e.image.height) + " texels, not the " +
                          std::to_string(slot_size_) + "x" + std::to_string(slot_size_) +
                          " of the tileset's tiles");
  }

  void blit_to_screen(int width, int height) const {
    glDisable(GL_FRAMEBUFFER_SRGB);
    glBlitNamedFramebuffer(color_fbo_.get(), 0, 0, 0, width_, height_, 0, 0, width, height,
                           GL_COLOR_BUFFER_BIT, GL_LINEAR);
  }

  const Geometry& geometry() const { return geometry_; }
  std::optional<Error> last_error() const { return last_error_; }
  std::optional<Error> last_tile_error() const { return last_tile_error_; }
  VirtualTextureOptions& options() { return options_; }
  // Read back from GL (what the driver was asked to allocate), not from the CPU-side table.
  std::uint64_t page_table_gpu_bytes() const { return texture_bytes(page_tex_.get(), 4); }
  std::uint64_t physical_gpu_bytes() const {
    if (format_ != PixelFormat::bc1) return texture_bytes(physical_tex_.get(), 4);
    // What the driver stores for the compressed level (0.5 byte per texel for S3TC DXT1).
    GLint compressed = 0, size = 0;
    glGetTextureLevelParameteriv(physical_tex_.get(), 0, GL_TEXTURE_COMPRESSED, &compressed);
    glGetTextureLevelParameteriv(physical_tex_.get(), 0, GL_TEXTURE_COMPRESSED_IMAGE_SIZE, &size);
    return compressed ? std::uint64_t(std::max(size, 0)) : 0;
  }
  PixelFormat tile_format() const { return format_; }
  static std::uint64_t texture_bytes(GLuint tex, std::uint64_t texel_bytes) {
    GLint w = 0, h = 0, d = 0;
    glGetTextureLevelParameteriv(tex, 0, GL_TEXTURE_WIDTH, &w);
    glGetTextureLevelParameteriv(tex, 0, GL_TEXTURE_HEIGHT, &h);
    glGetTextureLevelParameteriv(tex, 0, GL_TEXTURE_DEPTH, &d);
    return std::uint64_t(w) * std::uint64_t(h) * std::uint64_t(std::max(d, 1)) * texel_bytes;
  }

  const std::vector<TileRequest>& wanted() const { return stream_.wanted(); }
  double bias() const { return stream_.bias(); }

 private:
  struct Readback {
    GlBuffer buffer;
    GLsync fence = nullptr;
    std::uint64_t view_generation = 0;  // the view the feedback was rendered from
    std::size_t bytes = 0;
  };

  // A view differs from the last one when the scene, the size, the footprint or what the
  // corners and the centre see changed: "complete" then waits for feedback of the new view.
  void note_view(const Scene& scene) {
    std::vector<double> sig{double(width_), double(height_), scene.texels_per_pixel()};
    const double xs[] = {0.5, width_ * 0.5, width_ - 0.5};
    const double ys[] = {0.5, height_ * 0.5, height_ - 0.5};
    for (double y : ys) {
      for (double x : xs) {
        const UvHit h = scene.hit(x, y, width_, height_);
        sig.push_back(h ? h->first : -1e300);
        sig.push_back(h ? h->second : -1e300);
      }
    }
    const std::string name(scene.name());
    if (sig != view_signature_ || name != view_name_) {
      view_signature_ = std::move(sig);
      view_name_ = name;
      ++view_generation_;
    }
  }
  struct Upload {
    GlBuffer buffer;
    GLsync fence = nullptr;
  };

  void resize(int width, int height) {
    if (width == width_ && height == height_) return;
    width_ = width;
    height_ = height;
    const int k = options_.feedback_divisor;
    fb_w_ = std::max(1, (width + k - 1) / k);
    fb_h_ = std::max(1, (height + k - 1) / k);
    glCreateTextures(GL_TEXTURE_2D, 1, color_tex_.out());
    glTextureStorage2D(color_tex_.get(), 1, GL_SRGB8_ALPHA8, width, height);
    glNamedFramebufferTexture(color_fbo_.get(), GL_COLOR_ATTACHMENT0, color_tex_.get(), 0);
    glCreateTextures(GL_TEXTURE_2D, 1, feedback_tex_.out());
    glTextureStorage2D(feedback_tex_.get(), 1, GL_RG32UI, fb_w_, fb_h_);
    glNamedFramebufferTexture(feedback_fbo_.get(), GL_COLOR_ATTACHMENT0, feedback_tex_.get(), 0);
    // Feedback in flight was for the old size: drop it.
    const std::size_t bytes = std::size_t(fb_w_) * std::size_t(fb_h_) * 8;
    for (auto& r : readbacks_) {
      delete_fence(r.fence);
      glCreateBuffers(1, r.buffer.out());
      glNamedBufferStorage(r.buffer.get(), GLsizeiptr(bytes), nullptr, GL_MAP_READ_BIT);
      r.bytes = bytes;
    }
    ring_pos_ = 0;
  }

  // Processes the oldest feedback buffer whose fence has signalled (without waiting) into the
  // view's wanted list; returns 1 when one was processed. Each ring entry is reused only after it
  // was read.
  std::uint32_t collect_feedback(std::vector<TileRequest>& wanted) {
    auto& rb = readbacks_[ring_pos_];  // the oldest in flight is the next one to be written
    if (!rb.fence) return 0;
    // The ring is full: the oldest frame is readback_ring frames old, so this rarely waits.
    if (!fence_done(rb.fence, 1'000'000'000ull)) return 0;
    delete_fence(rb.fence);
    const auto* words = static_cast<const std::uint32_t*>(
        glMapNamedBufferRange(rb.buffer.get(), 0, GLsizeiptr(rb.bytes), GL_MAP_READ_BIT));
    if (!words) return 0;
    auto requests = feedback_.process(std::span(words, rb.bytes / 4), stream_.bias());
    wanted_generation_ = rb.view_generation;
    glUnmapNamedBuffer(rb.buffer.get());
    if (!requests) return 0;
    wanted = std::move(*requests);  // the stream updates the bias from it
    return 1;
  }

  // What the stream decided this frame, handed to the tile client.
  void issue(const StreamStep& step) {
    for (const TileId t : step.cancels) client_->cancel(t);
    for (const TileRequest& r : step.requests) client_->request(r.tile, double(r.coverage));
  }

  // Moves decoded tiles into slots, within the per-frame budget. Returns the tiles uploaded.
  std::uint32_t upload_tiles(std::uint64_t& bytes_out) {
    // Take no more from the client than a frame can upload (its queue is the back-pressure),
    // except until the root arrives: everything waits for it.
    std::vector<client::TileEvent> fresh;
    const std::size_t room =
        inbox_.size() < options_.upload_tiles ? options_.upload_tiles - inbox_.size() : 0;
    client_->poll(fresh, root_mapped_ ? room : 1u << 20);
    for (auto& e : fresh) inbox_.push_back(std::move(e));
    if (inbox_.empty()) return 0;

    auto& ring = uploads_[upload_pos_];
    upload_pos_ = (upload_pos_ + 1) % uploads_.size();
    fence_done(ring.fence, 1'000'000'000ull);
    delete_fence(ring.fence);
    std::uint8_t* mapped = nullptr;
    std::uint64_t used = 0;
    std::uint32_t count = 0;
    const TileId root{};

    for (std::size_t i = 0; i < inbox_.size();) {
      if (count >= options_.upload_tiles || used + tile_bytes_ > options_.upload_bytes) break;
      client::TileEvent& e = inbox_[i];
      if (!root_mapped_ && !(e.id == root)) {  // nothing maps before the root
        ++i;
        continue;
      }
      const bool well_formed = e.kind == client::TileEvent::Kind::decoded &&
                               e.image.format == format_ && e.image.width == slot_size_ &&
                               e.image.height == slot_size_ && e.image.pixels.size() == tile_bytes_;
      if (e.kind == client::TileEvent::Kind::absent) {
        stream_.absent(e.id);
      } else if (!well_formed) {  // an error, or a tile of the wrong size or format
        stream_.failed(e.id, Clock::now());
        last_tile_error_ = tile_error(e);
      }
      // Placed, or (already resident, or no slot may be taken this frame) given back.
      const auto got = well_formed ? stream_.place(e.id) : std::nullopt;
      if (!got) {
        if (e.kind == client::TileEvent::Kind::decoded) client_->release(e.id);
        inbox_.erase(inbox_.begin() + std::ptrdiff_t(i));
        continue;
      }
      if (got->evicted) {
        (void)table_.unmap(*got->evicted);
        client_->release(*got->evicted);
      }
      if (!mapped) {
        mapped = static_cast<std::uint8_t*>(
            glMapNamedBufferRange(ring.buffer.get(), 0, GLsizeiptr(options_.upload_bytes),
                                  GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT));
        if (!mapped) break;
      }
      const bool e_is_root = e.id == root;
      std::memcpy(mapped + used, e.image.pixels.data(), tile_bytes_);
      staged_.push_back({got->slot, used});
      used += tile_bytes_;
      ++count;
      (void)table_.map(e.id, got->slot);
      if (e_is_root) root_mapped_ = true;  // the stream pinned it
      inbox_.erase(inbox_.begin() + std::ptrdiff_t(i));
      if (e_is_root) i = 0;  // the tiles held back for the root may go now
    }
    if (mapped) {
      glUnmapNamedBuffer(ring.buffer.get());
      glBindBuffer(GL_PIXEL_UNPACK_BUFFER, ring.buffer.get());
      glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
      glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
      const bool compressed = format_ == PixelFormat::bc1;
      for (const auto& s : staged_) {
        const GLint x = GLint((s.slot % slots_per_row_) * slot_size_);
        const GLint y = GLint((s.slot / slots_per_row_) * slot_size_);
        const auto* offset = reinterpret_cast<const void*>(s.offset);
        if (compressed) {  // slot origins and sizes are multiples of the 4 x 4 block
          glCompressedTextureSubImage2D(physical_tex_.get(), 0, x, y, GLsizei(slot_size_),
                                        GLsizei(slot_size_), physical_format(format_),
                                        GLsizei(tile_bytes_), offset);
        } else {
          glTextureSubImage2D(physical_tex_.get(), 0, x, y, GLsizei(slot_size_),
                              GLsizei(slot_size_), GL_RGBA, GL_UNSIGNED_BYTE, offset);
        }
      }
      glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
      ring.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    }
    staged_.clear();
    bytes_out = used;
    return count;
  }

  void recenter(std::pair<double, double> focus) {
    const int maxz = geometry_.max_zoom();
    const double t = geometry_.tile_size();
    for (int z = 0; z <= maxz; ++z) {
      const double scale = std::ldexp(1.0, maxz - z) * t;
      const double cx = std::clamp(std::floor(focus.first / scale), 0.0, 4294967295.0);
      const double cy = std::clamp(std::floor(focus.second / scale), 0.0, 4294967295.0);
      table_.recenter(z, std::uint32_t(cx), std::uint32_t(cy));
    }
  }

  void upload_page_table() {
    const auto spans = table_.take_dirty();
    if (spans.empty()) return;
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    const std::uint32_t w = table_.window();
    for (const auto& s : spans) {
      const auto layer = table_.layer(s.layer);
      glTextureSubImage3D(page_tex_.get(), 0, GLint(s.x0), GLint(s.row), s.layer,
                          GLsizei(s.x1 - s.x0), 1, 1, GL_RED_INTEGER, GL_UNSIGNED_INT,
                          layer.data() + std::size_t(s.row) * w + s.x0);
    }
  }

  void fill_stats(FrameStats& st) const {
    const auto& wanted = stream_.wanted();
    const std::uint32_t missing = stream_.missing();
    const auto ss = stream_.slots().stats();
    st.wanted = std::uint32_t(wanted.size());
    st.wanted_missing = missing;
    st.resident = std::uint32_t(ss.resident);
    st.pending = std::uint32_t(stream_.pending());
    st.mip_bias = stream_.bias();
    st.hit_ratio = wanted.empty() ? 1.0 : double(wanted.size() - missing) / double(wanted.size());
    st.evictions = ss.evictions;
    st.refusals = ss.refusals;
    st.absent = stream_.absent_count();
    st.errors = stream_.failure_count() + error_count_;
    st.complete = root_mapped_ && wanted_generation_ == view_generation_ && !wanted.empty() &&
                  missing == 0 && stream_.pending() == 0 && inbox_.empty();
  }

  std::shared_ptr<client::TileClient> client_;
  Geometry geometry_;
  PixelFormat format_;  // of the decoded tiles, the upload ring and the physical texture
  Pyramid pyramid_;
  ClipmapPageTable table_;
  TileStream stream_;  // requests, cancellations, back-off and residency (the slot cache)
  FeedbackProcessor feedback_;
  VirtualTextureOptions options_;

  std::unordered_map<std::string, Programs> programs_;  // by scene GLSL
  std::optional<Error> last_error_;
  std::optional<Error> last_tile_error_;  // the latest tile that failed, named
  GlProgram debug_prog_;
  GlVertexArray vao_;
  GlTexture page_tex_, physical_tex_, color_tex_, feedback_tex_;
  GlFramebuffer color_fbo_, feedback_fbo_;
  std::uint32_t slot_size_ = 0, slots_per_row_ = 0, atlas_w_ = 0, atlas_h_ = 0;
  std::uint64_t tile_bytes_ = 0;
  int width_ = 0, height_ = 0, fb_w_ = 0, fb_h_ = 0;

  std::vector<Readback> readbacks_;
  std::size_t ring_pos_ = 0;
  std::vector<Upload> uploads_;
  std::size_t upload_pos_ = 0;
  struct Staged {
    std::uint32_t slot;
    std::uint64_t offset;
  };
  std::vector<Staged> staged_;

  std::uint64_t frame_ = 0;
  bool root_mapped_ = false;
  std::uint64_t wanted_generation_ =
      0;  // view generation of the feedback the wanted list came from
  std::uint64_t view_generation_ = 0;
  std::vector<double> view_signature_;
  std::string view_name_;
  std::deque<client::TileEvent> inbox_;
  std::uint64_t error_count_ = 0;  // programs that failed to build
};

Result<std::unique_ptr<VirtualTexture>> VirtualTexture::create(
    std::shared_ptr<client::TileClient> client, const Geometry& geometry,
    VirtualTextureOptions options) {
  if (!client) return Error{ErrorCode::invalid_argument, "no tile client"};
  if (options.slots < 2 || options.slots > VirtualTextureOptions::kMaxSlots) {
    return Error{ErrorCode::invalid_argument, "the physical texture needs 2 to " +
                                                  std::to_string(VirtualTextureOptions::kMaxSlots) +
                                                  " slots, not " + std::to_string(options.slots)};
  }
  if (!valid_divisor(options.feedback_divisor)) {
    return Error{ErrorCode::invalid_argument, "feedback divisor " +
                                                  std::to_string(options.feedback_divisor) +
                                                  " is not one of 1, 2, 4, 8, 16"};
  }
  if (options.readback_ring < 1 || options.readback_ring > 16) {
    return Error{ErrorCode::invalid_argument, "readback ring must hold 1 to 16 frames"};
  }
  if (options.upload_tiles < 1) {
    return Error{ErrorCode::invalid_argument, "the upload budget must allow one tile a frame"};
  }
  if (options.anisotropy < 1 || options.anisotropy > 16) {
    return Error{ErrorCode::invalid_argument,
                 "anisotropy " + std::to_string(options.anisotropy) + " is outside 1 to 16 taps"};
  }
  if (geometry.width() > (1u << 30) || geometry.height() > (1u << 30)) {
    return Error{ErrorCode::unsupported, "images wider or taller than 2^30 texels"};
  }
  auto pyramid = Pyramid::from_geometry(geometry);
  if (!pyramid) return pyramid.error();
  auto table = ClipmapPageTable::create(*pyramid, {options.window});
  if (!table) return table.error();
  if (epoxy_gl_version() < 45) {
    return Error{ErrorCode::unsupported, "the virtual texture needs a current OpenGL 4.5 context"};
  }
  // The tiles' format follows the tileset's codec (a property of the tileset).
  const CodecId codec = client->info().info.codec;
  const PixelFormat format = codec == CodecId::bc1 ? PixelFormat::bc1 : PixelFormat::rgba8;
  if (format == PixelFormat::bc1) {
    if (geometry.stored_size() % 4 != 0) {
      return Error{ErrorCode::unsupported,
                   "bc1 slots must be whole 4 x 4 blocks, but the stored tile size T + 2B = " +
                       std::to_string(geometry.tile_size()) + " + 2 x " +
                       std::to_string(geometry.border()) + " = " +
                       std::to_string(geometry.stored_size()) + " is not a multiple of 4"};
    }
    for (const char* ext : {"GL_EXT_texture_compression_s3tc", "GL_EXT_texture_sRGB"}) {
      if (!epoxy_has_gl_extension(ext)) {
        return Error{ErrorCode::unsupported,
                     std::string("a bc1 tileset needs sRGB S3TC textures, but this GL (") +
                         gl_renderer() + ") lacks " + ext};
      }
    }
  }
  auto impl = std::make_unique<Impl>(std::move(client), geometry, format, *pyramid,
                                     std::move(*table), options);
  if (auto s = impl->init(); !s) return s.error();
  return std::unique_ptr<VirtualTexture>(new VirtualTexture(std::move(impl)));
}

VirtualTexture::VirtualTexture(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
VirtualTexture::~VirtualTexture() = default;

FrameStats VirtualTexture::render(const Scene& scene, int width, int height) {
  VTS_GL_CALL_SITE("VirtualTexture::render");
  return impl_->render(scene, width, height);
}
FrameStats VirtualTexture::render(const PlaneView& view, int width, int height) {
  VTS_GL_CALL_SITE("VirtualTexture::render");
  return impl_->render(PlaneScene(view), width, height);
}
Image VirtualTexture::read_image() const {
  VTS_GL_CALL_SITE("VirtualTexture::read_image");
  return impl_->read_image();
}
std::optional<Error> VirtualTexture::last_error() const {
  return impl_->last_error();
}
std::optional<Error> VirtualTexture::last_tile_error() const {
  return impl_->last_tile_error();
}
void VirtualTexture::blit_to_screen(int width, int height) const {
  VTS_GL_CALL_SITE("VirtualTexture::blit_to_screen");
  impl_->blit_to_screen(width, height);
}
const std::vector<TileRequest>& VirtualTexture::last_wanted() const {
  return impl_->wanted();
}

double VirtualTexture::mip_bias() const {
  return impl_->bias();
}

void VirtualTexture::set_debug_view(DebugView view) {
  impl_->options().debug = view;
}
DebugView VirtualTexture::debug_view() const {
  return const_cast<Impl&>(*impl_).options().debug;
}
const Geometry& VirtualTexture::geometry() const {
  return impl_->geometry();
}
const VirtualTextureOptions& VirtualTexture::options() const {
  return const_cast<Impl&>(*impl_).options();
}
std::uint64_t VirtualTexture::page_table_gpu_bytes() const {
  VTS_GL_CALL_SITE("VirtualTexture::page_table_gpu_bytes");
  return impl_->page_table_gpu_bytes();
}
std::uint64_t VirtualTexture::physical_gpu_bytes() const {
  VTS_GL_CALL_SITE("VirtualTexture::physical_gpu_bytes");
  return impl_->physical_gpu_bytes();
}
PixelFormat VirtualTexture::tile_format() const {
  return impl_->tile_format();
}

}  // namespace vts::renderer
