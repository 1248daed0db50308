// Internals shared by the clipmap renderer's two meshes: render_clipmap.cpp (the footprints, the
// textures, the shading, the frame) and render_tessellation.cpp (the tessellation patches). They need
// the current context of the thread that made it (renderer.h); none is thread-safe.
#pragma once

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <cstdint>
#include <functional>
#include <vector>

#include "runtime/clipmap.h"

namespace terrain::render::internal {

// GLSL after the #version line of the footprints' vertex shader and of the tessellation evaluation
// shader: the level's uniforms, the outputs the fragment shader reads, and clipmap_vertex(h), which
// puts a vertex at twice-grid position h (so that the tessellation's half-sample vertices are exact)
// with the transition morph and writes gl_Position.
extern const char* const kClipmapVertexGlsl;
// The terrain's fragment shader (both meshes).
extern const char* const kTerrainFragmentShader;

// A shader stage from the concatenation of its sources.
struct Stage {
  GLenum kind;
  std::vector<const char*> sources;
};
// Compiles and links the stages. Throws std::runtime_error with the info log on failure.
GLuint link(const std::vector<Stage>& stages);
// Throws std::runtime_error naming `step` when glGetError reports an error.
void check_gl(const char* step);

// Uniform locations of a terrain program (the same names in both meshes' programs).
struct TerrainUniforms {
  TerrainUniforms() = default;
  explicit TerrainUniforms(GLuint program);  // also binds the samplers to units 0..3
  GLint level = -1, n = -1, wrap_base = -1, g = -1, viewer = -1, active = -1, w = -1, transitions = -1,
        mvp = -1, coarse_layer = -1, coarse_scale = -1, light = -1, flat = -1, flat_rgb = -1, zrange = -1,
        shading = -1, eye = -1, haze_rgb = -1, haze_distance = -1, haze_max = -1, level_colours = -1,
        hillshade_light = -1, relief = -1, drape = -1, drape_rect = -1;
};

// The tessellation mesh (Song et al. 2016): per level, the corners of quads patches streamed into
// one vertex buffer and drawn as GL_PATCHES. The render region away from the finer level is cut by a
// fixed grid of kCell x kCell cells (each patch clamped to its part of the region); a frame one quad
// wide around the finer level is cut into patches of at most kFrame quads whose edges on the finer
// level's perimeter get the doubled factor.
class TessellationMesh {
 public:
  static constexpr int64_t kCell = 8, kFrame = 32;
  // Needs a current OpenGL 4.5 context (tessellation shaders are core there). Throws
  // std::runtime_error on GL errors (shader log included).
  TessellationMesh();
  ~TessellationMesh();
  TessellationMesh(const TessellationMesh&) = delete;
  TessellationMesh& operator=(const TessellationMesh&) = delete;
  GLuint program() const { return program_; }
  const TerrainUniforms& uniforms() const { return uniforms_; }
  // Draws the render region of a level, active region a minus the finer level's active region
  // `inner` (this level's units; empty when none), with program() current and the level's uniforms
  // set: the patches whose piece `visible` keeps (`pieces` counts them); `raise` doubles the factor
  // of the edges on inner's boundary (false leaves T-junctions). Returns the patches drawn.
  int draw_level(const runtime::LevelRegion& a, const runtime::LevelRegion& inner, bool raise,
                 const std::function<bool(const runtime::LevelRegion&)>& visible, int& pieces);

 private:
  GLuint program_ = 0, vao_ = 0, vbo_ = 0;
  TerrainUniforms uniforms_;
  GLint u_inner_ = -1;
  std::vector<int32_t> corners_;  // x, y of 4 control points per patch
};

}  // namespace terrain::render::internal
