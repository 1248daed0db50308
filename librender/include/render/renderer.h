// Headless OpenGL 4.5 core renderer of a geometry clipmap (Asirvatham & Hoppe 2005, §2.3).
//
// The context comes from EGL without any window system: the Mesa surfaceless platform when
// present (llvmpipe on a machine without GPU), otherwise the default EGL display (a GPU driver);
// drawing goes to an RGBA8 + depth framebuffer object that is read back for PNG frames.
//
// Heights live in per-level layers of texture arrays (z, zc: n x n; the normal map: 2n x 2n),
// addressed toroidally exactly like the CPU clipmap; only the samples an update wrote are uploaded.
// Geometry comes from a few constant footprints in one vertex and one index buffer (A&H 2005
// §2.3.2): the m x m block (m = (n+1)/4; 12 per ring, 16 fill the finest level), the 2-quad-wide
// ring fix-up, the 1-quad-wide trim (the L-shaped gap left by the off-centre finer level) and a
// line of zero-area triangles on each ring's outer edge that stitches the T-junctions against the
// coarser level. The vertex shader translates (and for strips transposes) a footprint; a piece of
// a cropped active region clamps the footprint's local coordinates, collapsing the quads it does
// not need onto its edge.
//
// World frame: x = column * spacing, y = row * spacing (metres), z up (metres). A viewer looking
// along +y therefore looks "south" on a north-up map.
//
// Threads: OpenGL binds a context to one thread. HeadlessGL, every ClipmapRenderer and every call
// on them belong to the thread that made the context current; none is thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "runtime/clipmap.h"

namespace terrain::render {

struct Camera {
  double position[3] = {0, 0, 1000};  // metres
  double yaw = 0;                     // radians; 0 looks along +x, pi/2 along +y
  double pitch = -0.3;                // radians; negative looks down
  double fov_y_deg = 60;              // vertical field of view, degrees
  double near_m = 0;                  // near plane, metres; 0: from the height above the terrain
  double far_m = 0;                   // far plane, metres; 0: the coarsest level's extent
};

// How terrain pixels are coloured. Flat: a ramp over the frame's height range (green - tan - brown -
// white) times diffuse light on a uniform background (the look before issue 19). Hypsometric: map
// layer tints by absolute height (water blue at or below 0 m), hillshade from the normal maps lit from
// the north-west, a sky gradient and distance haze.
enum class Shading { Flat, Hypsometric };

// How each level's render region becomes triangles. Footprints: the constant vertex/index buffers of
// A&H 2005 (above), one draw call per block, zero-area stitches. Tessellation: Song et al. 2016 —
// only the corners of GL 4.5 quads patches go to the GPU (8 x 8-quad cells of a fixed grid of each
// level, each clamped to its part of the ring, and a one-quad frame around the finer level), one
// draw call per level; the tessellator makes one vertex per sample (always the level's full
// resolution: the clipmap's levels are the level of detail), the evaluation shader reads heights and
// morphs as the footprints' vertex shader does, and the frame's edges shared with the finer level get
// twice the factor (paper §3.3), so that they meet every vertex of the finer level's perimeter: no
// T-junction, no stitching triangle. Same vertices as the footprints, the tessellator's triangulation.
enum class Mesh { Footprints, Tessellation };

struct RenderOptions {
  bool transitions = true;           // geometry and normal morph near each ring's outer edge
  bool culling = true;               // per-block view-frustum culling against the z bounds
  bool stitch = true;                // zero-area triangles along each ring's outer edge (Footprints);
                                     // the doubled factor of the shared edges (Tessellation)
  bool snap_perimeter = true;        // with transitions off, still put the ring's outer vertices on
                                     // the coarser level; false leaves cracks (tests show they are caught)
  bool flat_colour = false;          // every terrain pixel gets `terrain_rgb` (crack tests)
  float terrain_rgb[3] = {1, 1, 1};  // linear 0..1
  float background_rgb[3] = {0.55f, 0.70f, 0.90f};  // linear 0..1
  float light_dir[3] = {-0.4f, -0.3f, 0.87f};       // towards the light, world frame (north is -y)
  float z_lo = 0, z_hi = 0;  // height colour ramp range, metres; z_hi <= z_lo: level 0's range (Flat)
  Shading shading = Shading::Hypsometric;
  float sky_zenith_rgb[3] = {0.22f, 0.42f, 0.75f};   // Hypsometric: sky straight up
  float sky_horizon_rgb[3] = {0.78f, 0.84f, 0.90f};  // ... at the horizon, and the haze colour
  double haze_distance_m = 0;  // distance of 1 - 1/e haze; 0: half the coarsest level's extent
  float haze_max = 0.85f;      // haze never hides more than this fraction; 0: no haze
  // Hypsometric hillshade: towards the sun (azimuth 315 degrees, altitude 45: the cartographic
  // north-west light; north is -y) and the slope exaggeration of the shading normal.
  float hillshade_dir[3] = {-0.5f, -0.5f, 0.7071f};
  float relief = 2.0f;
  bool drape = false;          // Hypsometric: colour from the image set_drape() gave, where it covers
  bool level_colours = false;  // tint each clipmap level (viewer toggle)
  bool wireframe = false;      // triangle edges only (viewer toggle)
  Mesh mesh = Mesh::Footprints;
};

struct RenderStats {
  int64_t triangles = 0;  // Footprints: submitted, zero-area stitching triangles included;
                          // Tessellation: what the tessellator generated (GL_PRIMITIVES_GENERATED)
  // Pieces drawn and culled: footprints' blocks, fix-ups and trims, or the tessellation's patches.
  int blocks_drawn = 0, blocks_culled = 0, draw_calls = 0;
  int patches = 0;               // Tessellation: quads patches drawn (= blocks_drawn); Footprints: 0
  int levels_drawn = 0;          // levels with a non-empty active region
  double seconds_upload = 0;     // texture uploads of the last upload()
  double seconds_render = 0;     // draw + glFinish
  double seconds_submit = 0;     // of seconds_render, the CPU's part: until the commands are issued
  double seconds_gpu = 0;        // the terrain's draws as the GPU timed them (GL_TIME_ELAPSED); 0 if none
  int64_t samples_uploaded = 0;  // height samples of the last upload()
};

// An EGL display + OpenGL 4.5 core context, current on the calling thread. Throws
// std::runtime_error (naming the EGL/GL step that failed) when no such context can be made.
class HeadlessGL {
 public:
  HeadlessGL();
  ~HeadlessGL();
  HeadlessGL(const HeadlessGL&) = delete;
  HeadlessGL& operator=(const HeadlessGL&) = delete;
  std::string renderer_name() const;  // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"; "?" if none
  std::string platform() const { return platform_; }  // "surfaceless" or "default" (the EGL display used)

 private:
  void* display_ = nullptr;
  void* context_ = nullptr;
  std::string platform_;
};

class ClipmapRenderer {
 public:
  // Needs a current context (HeadlessGL) that outlives the renderer; allocates textures for a
  // clipmap of n x n x levels and a width x height framebuffer. Throws std::invalid_argument for a
  // frame outside 1..16384 pixels a side, std::runtime_error on GL errors (shader log included).
  ClipmapRenderer(int n, int levels, int width, int height);
  ~ClipmapRenderer();
  ClipmapRenderer(const ClipmapRenderer&) = delete;
  ClipmapRenderer& operator=(const ClipmapRenderer&) = delete;

  // Uploads what the clipmap's last update wrote (dirty rectangles). Meant to follow every update;
  // a level whose clip region moved by more than those rectangles cover since this renderer last
  // uploaded it (updates without upload, a first upload, another clipmap) is uploaded whole, so the
  // textures never keep heights that the culling bounds, taken from the clipmap, do not describe.
  // `everything` uploads all levels with data. Throws std::invalid_argument when the clipmap's n or
  // level count differs from the renderer's, std::runtime_error on GL errors.
  void upload(const runtime::Clipmap& clipmap, bool everything = false);
  // Draws the clipmap's active regions into the framebuffer and waits for the GPU (the textures are
  // what the last upload() put there), with options.mesh's geometry. Throws as upload().
  RenderStats render(const runtime::Clipmap& clipmap, const Camera& camera, const RenderOptions& options);
  // An image draped over the terrain (RenderOptions::drape, Hypsometric shading): RGBA8, top row first,
  // covering world x0_m .. x0_m + width_m, y0_m .. y0_m + height_m (its first row at y0_m); its alpha
  // blends it over the height tints. Replaces an earlier drape. Throws std::invalid_argument for an
  // image outside 1..16384 pixels a side or not width * height * 4 bytes, std::runtime_error on GL errors.
  void set_drape(const std::vector<uint8_t>& rgba, int width, int height, double x0_m, double y0_m,
                 double width_m, double height_m);
  // Copies the last frame to the default framebuffer of the current context (a window), scaled to
  // width x height pixels. Throws std::runtime_error on GL errors.
  void blit_to_default_framebuffer(int width, int height) const;
  // Frame as RGBA8, top row first (out resized to width*height*4). Throws std::runtime_error on GL
  // errors.
  void read_rgba(std::vector<uint8_t>& out) const;
  int width() const { return width_; }
  int height() const { return height_; }
  double last_upload_seconds() const { return upload_seconds_; }
  int64_t last_upload_samples() const { return upload_samples_; }

 private:
  struct Gl;
  std::unique_ptr<Gl> gl_;
  int n_, levels_, width_, height_;
  double upload_seconds_ = 0;
  int64_t upload_samples_ = 0;
};

// Writes RGBA8 (top row first) as a PNG (any thread: no GL). Throws std::invalid_argument naming the
// path when rgba is not width * height * 4 bytes, Error(WriteFailed) naming it when writing fails.
void write_png_rgba(const std::string& path, int width, int height, const std::vector<uint8_t>& rgba);

}  // namespace terrain::render
