// The tessellation mesh of the clipmap renderer (Song et al. 2016): per level, only the corners of
// quads patches go to the GPU (cells of a fixed grid clamped to the ring, and a one-quad frame around
// the finer level); the tessellator makes the level's grid and the evaluation shader reads the
// heights. Cracks between levels: the frame's edges shared with the finer level's perimeter get twice
// their factor (paper §3.3), so their vertices fall on every perimeter vertex of the finer level,
// halfway between the coarser samples, at exactly the height the finer level's zc gives them there
// (0.5 (a + b), as the CPU computes it).
#include <algorithm>
#include <functional>
#include <stdexcept>

#include "render/internal/clipmap_gl.h"

namespace terrain::render::internal {

using runtime::LevelRegion;

namespace {

const char* const kPatchVertexShader = R"(#version 450 core
layout(location = 0) in ivec2 a_corner;  // level grid units
out ivec2 c_corner;
void main() { c_corner = a_corner; }
)";

// Control points: 0 and 1 the corners of the patch's domain, 2 and 3 those of the piece of it that
// is drawn (the rest collapses onto the piece's edges, as the footprints' clamped quads do). One
// vertex per sample: inner factors = the domain's quads, outer factors = its edges' quads, twice that
// on an edge shared with the finer level (its perimeter has a vertex per coarse half-unit); only
// unclamped patches (the frame around the finer level) lie on such an edge.
const char* const kControlShader = R"(#version 450 core
layout(vertices = 4) out;
in ivec2 c_corner[];
out ivec2 e_corner[];
uniform ivec4 u_inner;  // the finer level's active region x0 y0 x1 y1 (this level's units); 0: none
void main() {
  e_corner[gl_InvocationID] = c_corner[gl_InvocationID];
  if (gl_InvocationID == 0) {
    ivec2 lo = c_corner[0], hi = c_corner[1], e = hi - lo;
    bool whole = c_corner[2] == lo && c_corner[3] == hi;
    bool within_x = whole && lo.x >= u_inner.x && hi.x <= u_inner.z;
    bool within_y = whole && lo.y >= u_inner.y && hi.y <= u_inner.w;
    // Quads domain: outer 0 is the edge u = 0 (x = lo.x), 1 is v = 0 (y = lo.y), 2 is u = 1, 3 is v = 1.
    gl_TessLevelOuter[0] = float(within_y && lo.x == u_inner.z ? 2 * e.y : e.y);
    gl_TessLevelOuter[1] = float(within_x && lo.y == u_inner.w ? 2 * e.x : e.x);
    gl_TessLevelOuter[2] = float(within_y && hi.x == u_inner.x ? 2 * e.y : e.y);
    gl_TessLevelOuter[3] = float(within_x && hi.y == u_inner.y ? 2 * e.x : e.x);
    gl_TessLevelInner[0] = float(e.x);
    gl_TessLevelInner[1] = float(e.y);
  }
}
)";

// Generated vertices sit on samples, or halfway between them (a doubled edge; a patch 1 quad wide,
// whose inner factor the tessellator raises to 2): snapped to half units, which clipmap_vertex
// takes exactly, then clamped to the piece drawn.
const char* const kEvaluationHead = R"(#version 450 core
layout(quads, equal_spacing, ccw) in;
in ivec2 e_corner[];
)";
const char* const kEvaluationMain = R"(
void main() {
  vec2 p = mix(vec2(e_corner[0]), vec2(e_corner[1]), gl_TessCoord.xy);
  clipmap_vertex(clamp(ivec2(round(2.0 * p)), 2 * e_corner[2], 2 * e_corner[3]));
}
)";

int64_t floor_to(int64_t v, int64_t step) { return (v >= 0 ? v / step : -((-v + step - 1) / step)) * step; }

}  // namespace

TessellationMesh::TessellationMesh() {
  GLint max_level = 0;
  glGetIntegerv(GL_MAX_TESS_GEN_LEVEL, &max_level);
  if (max_level < 2 * kFrame)
    throw std::runtime_error("clipmap renderer: GL_MAX_TESS_GEN_LEVEL below 64, the OpenGL minimum");
  program_ = link({{GL_VERTEX_SHADER, {kPatchVertexShader}},
                   {GL_TESS_CONTROL_SHADER, {kControlShader}},
                   {GL_TESS_EVALUATION_SHADER, {kEvaluationHead, kClipmapVertexGlsl, kEvaluationMain}},
                   {GL_FRAGMENT_SHADER, {kTerrainFragmentShader}}});
  uniforms_ = TerrainUniforms(program_);
  u_inner_ = glGetUniformLocation(program_, "u_inner");
  glCreateBuffers(1, &vbo_);
  glCreateVertexArrays(1, &vao_);
  glEnableVertexArrayAttrib(vao_, 0);
  glVertexArrayAttribIFormat(vao_, 0, 2, GL_INT, 0);
  glVertexArrayAttribBinding(vao_, 0, 0);
  check_gl("tessellation setup");
}

TessellationMesh::~TessellationMesh() {
  glDeleteBuffers(1, &vbo_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteProgram(program_);
}

int TessellationMesh::draw_level(const LevelRegion& a, const LevelRegion& inner, bool raise,
                                 const std::function<bool(const LevelRegion&)>& visible, int& pieces) {
  corners_.clear();
  auto patch = [&](const LevelRegion& domain, const LevelRegion& piece) {
    if (piece.empty() || !visible(piece)) return;
    ++pieces;
    for (int64_t v : {domain.x0, domain.y0, domain.x1, domain.y1, piece.x0, piece.y0, piece.x1, piece.y1})
      corners_.push_back(int32_t(v));
  };
  // The ring away from the finer level: cells of the level's fixed kCell grid, each clamped to the
  // part of it in r. The tessellator's triangulation is symmetric about each patch's centre (its
  // diagonals flip there); fixed cells keep it in place while the level moves, patches that followed
  // the moving blocks flipped diagonals all over the level at every shift (a pop).
  auto cells = [&](const LevelRegion& r) {
    if (r.empty()) return;
    for (int64_t cy = floor_to(r.y0, kCell); cy < r.y1; cy += kCell)
      for (int64_t cx = floor_to(r.x0, kCell); cx < r.x1; cx += kCell) {
        const LevelRegion cell{cx, cy, cx + kCell, cy + kCell};
        patch(cell, LevelRegion{std::max(cx, r.x0), std::max(cy, r.y0), std::min(cell.x1, r.x1),
                                std::min(cell.y1, r.y1)});
      }
  };
  if (inner.empty()) {
    cells(a);
  } else {
    // A frame one quad wide around the finer level: unclamped patches whose edges on the finer
    // level's perimeter get the doubled factor (at most kFrame quads long, so 2 kFrame <= 64),
    // cut on the fixed grid too.
    const LevelRegion h{inner.x0 - 1, inner.y0 - 1, inner.x1 + 1, inner.y1 + 1};
    cells(LevelRegion{a.x0, a.y0, a.x1, h.y0});
    cells(LevelRegion{a.x0, h.y1, a.x1, a.y1});
    cells(LevelRegion{a.x0, h.y0, h.x0, h.y1});
    cells(LevelRegion{h.x1, h.y0, a.x1, h.y1});
    auto run = [&](int64_t s0, int64_t s1, auto&& piece_at) {
      for (int64_t s = s0; s < s1;) {
        const int64_t e = std::min(s1, floor_to(s, kFrame) + kFrame);
        const LevelRegion p = piece_at(s, e);
        patch(p, p);
        s = e;
      }
    };
    for (const int64_t y : {h.y0, inner.y1}) {
      patch(LevelRegion{h.x0, y, inner.x0, y + 1}, LevelRegion{h.x0, y, inner.x0, y + 1});  // corners
      patch(LevelRegion{inner.x1, y, h.x1, y + 1}, LevelRegion{inner.x1, y, h.x1, y + 1});
      run(inner.x0, inner.x1, [&](int64_t s, int64_t e) { return LevelRegion{s, y, e, y + 1}; });
    }
    for (const int64_t x : {h.x0, inner.x1})
      run(inner.y0, inner.y1, [&](int64_t s, int64_t e) { return LevelRegion{x, s, x + 1, e}; });
  }
  const int patches = int(corners_.size() / 8);
  if (patches == 0) return 0;
  if (raise && !inner.empty())
    glUniform4i(u_inner_, GLint(inner.x0), GLint(inner.y0), GLint(inner.x1), GLint(inner.y1));
  else
    glUniform4i(u_inner_, 0, 0, 0, 0);
  // A new store per level: the driver keeps the previous one alive for the draws still pending.
  glNamedBufferData(vbo_, GLsizeiptr(corners_.size() * sizeof(int32_t)), corners_.data(), GL_STREAM_DRAW);
  glVertexArrayVertexBuffer(vao_, 0, vbo_, 0, 2 * sizeof(int32_t));
  glBindVertexArray(vao_);
  glPatchParameteri(GL_PATCH_VERTICES, 4);
  glDrawArrays(GL_PATCHES, 0, GLsizei(4 * patches));
  return patches;
}

}  // namespace terrain::render::internal
