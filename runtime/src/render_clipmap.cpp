// Drawing a geometry clipmap with OpenGL 4.5 core: toroidal height textures read in the vertex
// shader, footprints generated from gl_VertexID, transition morph, T-junction stitching, per-block
// view-frustum culling, z-coloured diffuse shading from the slope (normal) maps.
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "runtime/renderer.h"

namespace terrain::runtime {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

const char* kVertexShader = R"(#version 450 core
uniform ivec2 u_origin;      // first vertex of the footprint, level grid
uniform int u_cols;          // grid footprint: quads per row
uniform int u_mode;          // 0: grid of quads, 1: zero-area stitching triangles along u_dir
uniform ivec2 u_dir;
uniform int u_level;
uniform int u_n;
uniform ivec2 u_wrap_base;   // a multiple of n making every vertex coordinate non-negative
uniform float u_g;           // metres per level unit
uniform vec2 u_viewer;       // viewer, level grid units
uniform ivec4 u_active;      // active region x0 y0 x1 y1
uniform float u_w;           // transition width
uniform int u_transitions;  // 2: morph, 1: only the perimeter snaps to the coarser level, 0: nothing
uniform mat4 u_mvp;
uniform sampler2DArray u_z;
uniform sampler2DArray u_zc;
out vec2 v_grid;
out float v_alpha;
out float v_height;
invariant gl_Position;

// Triangulation of a quad: diagonal (0,0)-(1,1), the one the clipmap's zc assumes.
const ivec2 kCorners[6] = ivec2[6](ivec2(0, 0), ivec2(1, 0), ivec2(1, 1), ivec2(0, 0), ivec2(1, 1), ivec2(0, 1));

void main() {
  ivec2 g;
  if (u_mode == 0) {
    int q = gl_VertexID / 6;
    g = u_origin + ivec2(q % u_cols, q / u_cols) + kCorners[gl_VertexID % 6];
  } else {
    g = u_origin + u_dir * (2 * (gl_VertexID / 3) + gl_VertexID % 3);
  }
  ivec3 t = ivec3((g + u_wrap_base) % u_n, u_level);
  float zf = texelFetch(u_z, t, 0).r;
  float zc = texelFetch(u_zc, t, 0).r;
  // Distance to the active region's edge: alpha must be exactly 1 on the perimeter (watertight
  // against the coarser level) and exactly 0 on the finer level's perimeter.
  vec2 d = vec2(min(g - u_active.xy, u_active.zw - g));
  vec2 a;
  if (u_transitions == 2) {
    // L&H 2004 §6.2: a ramp that tracks the continuous viewer position (no popping), joined by a
    // ramp from the edge itself for regions cropped off-centre.
    vec2 half_extent = vec2(u_active.zw - u_active.xy) * 0.5;
    a = clamp((abs(vec2(g) - u_viewer) - (half_extent - u_w - 1.0)) / u_w, 0.0, 1.0);
    a = max(a, clamp((u_w - d) / u_w, 0.0, 1.0));
  } else if (u_transitions == 1) {
    a = vec2(d.x == 0.0 ? 1.0 : 0.0, d.y == 0.0 ? 1.0 : 0.0);
  } else {
    a = vec2(0.0);
  }
  float alpha = max(a.x, a.y);
  float z = (1.0 - alpha) * zf + alpha * zc;
  v_grid = vec2(g);
  v_alpha = alpha;
  v_height = z;
  gl_Position = u_mvp * vec4(vec2(g) * u_g, z, 1.0);
}
)";

const char* kFragmentShader = R"(#version 450 core
in vec2 v_grid;
in float v_alpha;
in float v_height;
uniform sampler2DArray u_slope;  // dz/dx, dz/dy; linear filtering, repeat = toroidal wrap
uniform int u_level;
uniform int u_coarse_layer;
uniform float u_coarse_scale;    // 0.5: the coarser level's grid, 1: level 0 (no coarser level)
uniform int u_n;
uniform vec3 u_light;
uniform int u_flat;
uniform vec3 u_flat_rgb;
uniform vec2 u_zrange;
out vec4 o_colour;

vec3 ramp(float t) {
  const vec3 c0 = vec3(0.20, 0.45, 0.20), c1 = vec3(0.55, 0.60, 0.30), c2 = vec3(0.50, 0.40, 0.30),
             c3 = vec3(0.95, 0.95, 0.97);
  if (t < 0.33) return mix(c0, c1, t / 0.33);
  if (t < 0.75) return mix(c1, c2, (t - 0.33) / 0.42);
  return mix(c2, c3, (t - 0.75) / 0.25);
}

void main() {
  if (u_flat != 0) {
    o_colour = vec4(u_flat_rgb, 1.0);
    return;
  }
  float n = float(u_n);
  vec2 sf = texture(u_slope, vec3((v_grid + 0.5) / n, float(u_level))).rg;
  vec2 sc = texture(u_slope, vec3((v_grid * u_coarse_scale + 0.5) / n, float(u_coarse_layer))).rg;
  vec2 s = mix(sf, sc, v_alpha);
  vec3 normal = normalize(vec3(-s, 1.0));
  float diffuse = max(dot(normal, normalize(u_light)), 0.0);
  float t = clamp((v_height - u_zrange.x) / max(u_zrange.y - u_zrange.x, 1e-3), 0.0, 1.0);
  o_colour = vec4(ramp(t) * (0.25 + 0.75 * diffuse), 1.0);
}
)";

GLuint compile(GLenum kind, const char* src) {
  GLuint s = glCreateShader(kind);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("clipmap renderer: shader compile failed: ") + log);
  }
  return s;
}

void check_gl(const char* step) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) {
    char code[16];
    std::snprintf(code, sizeof code, "0x%04X", unsigned(e));
    throw std::runtime_error(std::string("clipmap renderer: OpenGL error ") + code + " in " + step);
  }
}

using Mat4 = std::array<double, 16>;  // column-major, like GL

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[size_t(k * 4 + row)] * b[size_t(c * 4 + k)];
      r[size_t(c * 4 + row)] = s;
    }
  return r;
}

Mat4 view_projection(const Camera& cam, double aspect, double near_m, double far_m) {
  const double cp = std::cos(cam.pitch), sp = std::sin(cam.pitch), cy = std::cos(cam.yaw), sy = std::sin(cam.yaw);
  const double f[3] = {cp * cy, cp * sy, sp};
  // right = f x up(0,0,1), normalised; up' = right x f
  double r[3] = {f[1], -f[0], 0};
  const double rl = std::hypot(r[0], r[1]);
  if (rl < 1e-9) r[0] = 1, r[1] = 0;  // looking straight up or down: any right vector will do
  else r[0] /= rl, r[1] /= rl;
  const double u[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]};
  const double* e = cam.position;
  Mat4 view{r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
            -(r[0] * e[0] + r[1] * e[1] + r[2] * e[2]), -(u[0] * e[0] + u[1] * e[1] + u[2] * e[2]),
            (f[0] * e[0] + f[1] * e[1] + f[2] * e[2]), 1};
  const double t = 1.0 / std::tan(cam.fov_y_deg * M_PI / 360.0);
  Mat4 proj{t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far_m + near_m) / (near_m - far_m), -1,
            0, 0, 2 * far_m * near_m / (near_m - far_m), 0};
  return multiply(proj, view);
}

// The frustum's planes (a, b, c, d), inside where a x + b y + c z + d >= 0 (Gribb & Hartmann).
std::array<std::array<double, 4>, 6> frustum_planes(const Mat4& m) {
  std::array<std::array<double, 4>, 6> p{};
  for (int i = 0; i < 3; ++i)
    for (int s = 0; s < 2; ++s)
      for (int k = 0; k < 4; ++k) {
        const double row_w = m[size_t(k * 4 + 3)], row_i = m[size_t(k * 4 + i)];
        p[size_t(2 * i + s)][size_t(k)] = s == 0 ? row_w + row_i : row_w - row_i;
      }
  return p;
}

bool box_outside(const std::array<std::array<double, 4>, 6>& planes, const double lo[3], const double hi[3]) {
  for (const auto& p : planes) {
    // The box corner furthest along the plane normal; if even that one is outside, all are.
    const double x = p[0] >= 0 ? hi[0] : lo[0], y = p[1] >= 0 ? hi[1] : lo[1], z = p[2] >= 0 ? hi[2] : lo[2];
    if (p[0] * x + p[1] * y + p[2] * z + p[3] < 0) return true;
  }
  return false;
}

}  // namespace

struct ClipmapRenderer::Gl {
  GLuint program = 0, vao = 0, fbo = 0, colour = 0, depth = 0;
  GLuint tex_z = 0, tex_zc = 0, tex_slope = 0;
  GLint u_origin = -1, u_cols = -1, u_mode = -1, u_dir = -1, u_level = -1, u_n = -1, u_wrap_base = -1, u_g = -1,
        u_viewer = -1, u_active = -1, u_w = -1, u_transitions = -1, u_mvp = -1, u_coarse_layer = -1,
        u_coarse_scale = -1, u_light = -1, u_flat = -1, u_flat_rgb = -1, u_zrange = -1;
};

ClipmapRenderer::ClipmapRenderer(int n, int levels, int width, int height)
    : gl_(std::make_unique<Gl>()), n_(n), levels_(levels), width_(width), height_(height) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    throw std::invalid_argument("clipmap renderer: frame size must be 1..16384 pixels a side");
  Gl& g = *gl_;
  const GLuint vs = compile(GL_VERTEX_SHADER, kVertexShader), fs = compile(GL_FRAGMENT_SHADER, kFragmentShader);
  g.program = glCreateProgram();
  glAttachShader(g.program, vs);
  glAttachShader(g.program, fs);
  glLinkProgram(g.program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(g.program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetProgramInfoLog(g.program, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("clipmap renderer: program link failed: ") + log);
  }
  auto loc = [&](const char* name) { return glGetUniformLocation(g.program, name); };
  g.u_origin = loc("u_origin"), g.u_cols = loc("u_cols"), g.u_mode = loc("u_mode"), g.u_dir = loc("u_dir");
  g.u_level = loc("u_level"), g.u_n = loc("u_n"), g.u_wrap_base = loc("u_wrap_base"), g.u_g = loc("u_g");
  g.u_viewer = loc("u_viewer"), g.u_active = loc("u_active"), g.u_w = loc("u_w"), g.u_transitions = loc("u_transitions");
  g.u_mvp = loc("u_mvp"), g.u_coarse_layer = loc("u_coarse_layer"), g.u_coarse_scale = loc("u_coarse_scale");
  g.u_light = loc("u_light"), g.u_flat = loc("u_flat"), g.u_flat_rgb = loc("u_flat_rgb"), g.u_zrange = loc("u_zrange");
  glUseProgram(g.program);
  glUniform1i(loc("u_z"), 0);
  glUniform1i(loc("u_zc"), 1);
  glUniform1i(loc("u_slope"), 2);
  glCreateVertexArrays(1, &g.vao);  // core profile needs one, even without attributes

  auto make_array = [&](GLuint& tex, GLenum format, bool linear) {
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &tex);
    glTextureStorage3D(tex, 1, format, n, n, levels);
    glTextureParameteri(tex, GL_TEXTURE_MIN_FILTER, linear ? GL_LINEAR : GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_MAG_FILTER, linear ? GL_LINEAR : GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_WRAP_S, GL_REPEAT);  // repeat = the toroidal wrap
    glTextureParameteri(tex, GL_TEXTURE_WRAP_T, GL_REPEAT);
  };
  make_array(g.tex_z, GL_R32F, false);
  make_array(g.tex_zc, GL_R32F, false);
  make_array(g.tex_slope, GL_RG32F, true);

  glCreateRenderbuffers(1, &g.colour);
  glNamedRenderbufferStorage(g.colour, GL_RGBA8, width, height);
  glCreateRenderbuffers(1, &g.depth);
  glNamedRenderbufferStorage(g.depth, GL_DEPTH_COMPONENT24, width, height);
  glCreateFramebuffers(1, &g.fbo);
  glNamedFramebufferRenderbuffer(g.fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.colour);
  glNamedFramebufferRenderbuffer(g.fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.depth);
  if (glCheckNamedFramebufferStatus(g.fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error("clipmap renderer: framebuffer incomplete");
  check_gl("setup");
}

ClipmapRenderer::~ClipmapRenderer() {
  Gl& g = *gl_;
  const GLuint textures[3] = {g.tex_z, g.tex_zc, g.tex_slope};
  glDeleteTextures(3, textures);
  glDeleteFramebuffers(1, &g.fbo);
  glDeleteRenderbuffers(1, &g.colour);
  glDeleteRenderbuffers(1, &g.depth);
  glDeleteVertexArrays(1, &g.vao);
  glDeleteProgram(g.program);
}

void ClipmapRenderer::upload(const Clipmap& cm, bool everything) {
  if (cm.n() != n_ || cm.level_count() != levels_)
    throw std::invalid_argument("clipmap renderer: clipmap size differs from the renderer's");
  const auto t0 = Clock::now();
  Gl& g = *gl_;
  upload_samples_ = 0;
  glPixelStorei(GL_UNPACK_ROW_LENGTH, n_);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  for (int l = 0; l < levels_; ++l) {
    if (!cm.has_data(l)) continue;
    std::vector<Rect> all;
    const std::vector<Rect>* rects = &cm.dirty_rects(l);
    if (everything) {
      all.push_back(cm.clip_region(l));
      rects = &all;
    }
    for (const Rect& r : *rects) {
      // A rectangle of the level maps to up to 2 x 2 pieces of the toroidal texture.
      const int64_t tx = cm.wrap(r.x0), ty = cm.wrap(r.y0);
      const int64_t wx[2] = {std::min<int64_t>(r.width, n_ - tx), r.width - std::min<int64_t>(r.width, n_ - tx)};
      const int64_t wy[2] = {std::min<int64_t>(r.height, n_ - ty), r.height - std::min<int64_t>(r.height, n_ - ty)};
      for (int py = 0; py < 2; ++py)
        for (int px = 0; px < 2; ++px) {
          if (wx[px] <= 0 || wy[py] <= 0) continue;
          const int64_t ox = px == 0 ? tx : 0, oy = py == 0 ? ty : 0;
          const size_t at = size_t(oy * n_ + ox);
          glTextureSubImage3D(g.tex_z, 0, GLint(ox), GLint(oy), l, GLsizei(wx[px]), GLsizei(wy[py]), 1, GL_RED, GL_FLOAT,
                              cm.heights(l) + at);
          glTextureSubImage3D(g.tex_zc, 0, GLint(ox), GLint(oy), l, GLsizei(wx[px]), GLsizei(wy[py]), 1, GL_RED, GL_FLOAT,
                              cm.coarse_heights(l) + at);
          glTextureSubImage3D(g.tex_slope, 0, GLint(ox), GLint(oy), l, GLsizei(wx[px]), GLsizei(wy[py]), 1, GL_RG,
                              GL_FLOAT, cm.slopes(l) + 2 * at);
          upload_samples_ += wx[px] * wy[py];
        }
    }
  }
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  check_gl("upload");
  upload_seconds_ = since(t0);
}

RenderStats ClipmapRenderer::render(const Clipmap& cm, const Camera& cam, const RenderOptions& opt) {
  if (cm.n() != n_ || cm.level_count() != levels_)
    throw std::invalid_argument("clipmap renderer: clipmap size differs from the renderer's");
  const auto t0 = Clock::now();
  Gl& g = *gl_;
  RenderStats stats;
  stats.seconds_upload = upload_seconds_;
  stats.samples_uploaded = upload_samples_;

  // Near plane from the height above the terrain, far plane beyond the coarsest level.
  const float ground = cm.terrain_height_at(cam.position[0], cam.position[1]);
  const double above = std::isnan(ground) ? 100.0 : std::max(cam.position[2] - double(ground), 0.0);
  const double near_m = cam.near_m > 0 ? cam.near_m : std::clamp(0.2 * above, 0.05, 500.0);
  const double far_m = cam.far_m > 0 ? cam.far_m : 2.0 * n_ * cm.spacing(0) + 2.0 * above;
  const Mat4 vp = view_projection(cam, double(width_) / double(height_), near_m, far_m);
  const auto planes = frustum_planes(vp);
  float mvp[16];
  for (int i = 0; i < 16; ++i) mvp[i] = float(vp[size_t(i)]);

  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, width_, height_);
  glClearColor(opt.background_rgb[0], opt.background_rgb[1], opt.background_rgb[2], 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDisable(GL_CULL_FACE);  // stitching triangles have no meaningful orientation
  glUseProgram(g.program);
  glBindVertexArray(g.vao);
  glBindTextureUnit(0, g.tex_z);
  glBindTextureUnit(1, g.tex_zc);
  glBindTextureUnit(2, g.tex_slope);
  glUniformMatrix4fv(g.u_mvp, 1, GL_FALSE, mvp);
  glUniform1i(g.u_n, n_);
  glUniform1i(g.u_transitions, opt.transitions ? 2 : opt.snap_perimeter ? 1 : 0);
  glUniform3f(g.u_light, opt.light_dir[0], opt.light_dir[1], opt.light_dir[2]);
  glUniform1i(g.u_flat, opt.flat_colour ? 1 : 0);
  glUniform3f(g.u_flat_rgb, opt.terrain_rgb[0], opt.terrain_rgb[1], opt.terrain_rgb[2]);
  if (opt.z_hi > opt.z_lo) {
    glUniform2f(g.u_zrange, opt.z_lo, opt.z_hi);
  } else {
    const ZRange zr = cm.z_bounds(0, cm.active_region(0));
    glUniform2f(g.u_zrange, zr.lo, zr.hi);
  }

  const int block = (n_ + 1) / 4 - 1;  // quads per side of the m x m block, m = (n+1)/4
  // Fine to coarse, so that nearer terrain fills the depth buffer first.
  for (int l = levels_ - 1; l >= 0; --l) {
    const LevelRegion a = cm.active_region(l);
    if (a.empty()) continue;
    ++stats.levels_drawn;
    const double gm = cm.spacing(l);
    const auto v = cm.viewer_grid(l);
    const Rect clip = cm.clip_region(l);
    const GLint base_x = GLint(n_ * (std::abs(clip.x0) / n_ + 2)), base_y = GLint(n_ * (std::abs(clip.y0) / n_ + 2));
    glUniform1i(g.u_level, l);
    glUniform2i(g.u_wrap_base, base_x, base_y);
    glUniform1f(g.u_g, float(gm));
    glUniform2f(g.u_viewer, float(v[0]), float(v[1]));
    glUniform4i(g.u_active, GLint(a.x0), GLint(a.y0), GLint(a.x1), GLint(a.y1));
    glUniform1f(g.u_w, float(cm.transition_width(l)));
    glUniform1i(g.u_coarse_layer, l > 0 ? l - 1 : 0);
    glUniform1f(g.u_coarse_scale, l > 0 ? 0.5f : 1.0f);

    // render region = active(l) - active(l+1), as up to four rectangles of quads.
    LevelRegion inner;
    if (l + 1 < levels_ && !cm.active_region(l + 1).empty()) {
      const LevelRegion f = cm.active_region(l + 1);
      inner = LevelRegion{f.x0 / 2, f.y0 / 2, f.x1 / 2, f.y1 / 2};
    }
    std::vector<LevelRegion> parts;
    if (inner.empty()) {
      parts.push_back(a);
    } else {
      parts.push_back(LevelRegion{a.x0, a.y0, a.x1, inner.y0});
      parts.push_back(LevelRegion{a.x0, inner.y1, a.x1, a.y1});
      parts.push_back(LevelRegion{a.x0, inner.y0, inner.x0, inner.y1});
      parts.push_back(LevelRegion{inner.x1, inner.y0, a.x1, inner.y1});
    }
    glUniform1i(g.u_mode, 0);
    for (const LevelRegion& p : parts) {
      for (int64_t by = p.y0; by < p.y1; by += block)
        for (int64_t bx = p.x0; bx < p.x1; bx += block) {
          const int64_t w = std::min<int64_t>(block, p.x1 - bx), h = std::min<int64_t>(block, p.y1 - by);
          if (opt.culling) {
            const ZRange zr = cm.z_bounds(l, LevelRegion{bx, by, bx + w, by + h});
            const double lo[3] = {double(bx) * gm, double(by) * gm, double(zr.lo)};
            const double hi[3] = {double(bx + w) * gm, double(by + h) * gm, double(zr.hi)};
            if (box_outside(planes, lo, hi)) {
              ++stats.blocks_culled;
              continue;
            }
          }
          glUniform2i(g.u_origin, GLint(bx), GLint(by));
          glUniform1i(g.u_cols, GLint(w));
          glDrawArrays(GL_TRIANGLES, 0, GLsizei(w * h * 6));
          ++stats.blocks_drawn;
          ++stats.draw_calls;
          stats.triangles += 2 * w * h;
        }
    }
    // Zero-area triangles (v0, v1, v2) on each outer side close the T-junctions against level l-1.
    if (opt.stitch && l > 0) {
      glUniform1i(g.u_mode, 1);
      const struct {
        int64_t x, y, dx, dy, len;
      } sides[4] = {{a.x0, a.y0, 1, 0, a.x1 - a.x0}, {a.x0, a.y1, 1, 0, a.x1 - a.x0},
                    {a.x0, a.y0, 0, 1, a.y1 - a.y0}, {a.x1, a.y0, 0, 1, a.y1 - a.y0}};
      for (const auto& s : sides) {
        glUniform2i(g.u_origin, GLint(s.x), GLint(s.y));
        glUniform2i(g.u_dir, GLint(s.dx), GLint(s.dy));
        glDrawArrays(GL_TRIANGLES, 0, GLsizei(s.len / 2 * 3));
        ++stats.draw_calls;
        stats.triangles += s.len / 2;
      }
    }
  }
  glFinish();
  check_gl("render");
  stats.seconds_render = since(t0);
  return stats;
}

void ClipmapRenderer::read_rgba(std::vector<uint8_t>& out) const {
  out.resize(size_t(width_) * size_t(height_) * 4);
  glBindFramebuffer(GL_FRAMEBUFFER, gl_->fbo);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, out.data());
  check_gl("read back");
  // GL rows start at the bottom; images start at the top.
  const size_t row = size_t(width_) * 4;
  for (int y = 0; y < height_ / 2; ++y)
    std::swap_ranges(out.begin() + ptrdiff_t(size_t(y) * row), out.begin() + ptrdiff_t(size_t(y + 1) * row),
                     out.begin() + ptrdiff_t(size_t(height_ - 1 - y) * row));
}

}  // namespace terrain::runtime
