// Drawing a geometry clipmap with OpenGL 4.5 core: toroidal height textures read in the vertex
// shader (or, for the tessellation mesh of render_tessellation.cpp, the evaluation shader),
// footprints from constant vertex/index buffers, transition morph, T-junction stitching, per-block
// view-frustum culling; shading from the slope (normal) maps: hypsometric tints with hillshade, a sky
// gradient and distance haze, or the plain relative-z ramp.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "render/internal/clipmap_gl.h"
#include "render/renderer.h"

namespace terrain::render {

using namespace terrain::runtime;  // the stage below

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

namespace internal {

const char* const kClipmapVertexGlsl = R"(
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
out vec3 v_world;            // metres, for the distance haze
invariant gl_Position;

// The level's triangulation at twice-grid position h: the sample, or halfway between two samples the
// midpoint of the quad edge or of the (0,0)-(1,1) diagonal, computed as the CPU computes zc there
// (0.5 (a + b)), so that a coarser level's vertex halfway between its samples meets the finer
// level's perimeter vertex (height zc) exactly.
float surface(sampler2DArray s, ivec2 h) {
  ivec2 w = h + 2 * u_wrap_base;
  ivec2 g = w >> 1, o = w & 1;
  float a = texelFetch(s, ivec3(g % u_n, u_level), 0).r;
  if (o.x == 0 && o.y == 0) return a;
  float b = texelFetch(s, ivec3((g + o) % u_n, u_level), 0).r;
  precise float m = 0.5 * (a + b);
  return m;
}

void clipmap_vertex(ivec2 h) {
  vec2 g = vec2(h) * 0.5;
  float zf = surface(u_z, h);
  float zc = surface(u_zc, h);
  // Distance to the active region's edge: alpha must be exactly 1 on the perimeter (watertight
  // against the coarser level) and exactly 0 on the finer level's perimeter.
  vec2 d = min(g - vec2(u_active.xy), vec2(u_active.zw) - g);
  vec2 a;
  if (u_transitions == 2) {
    // L&H 2004 §6.2: a ramp that tracks the continuous viewer position (no popping), joined by a
    // ramp from the edge itself for regions cropped off-centre.
    vec2 half_extent = vec2(u_active.zw - u_active.xy) * 0.5;
    a = clamp((abs(g - u_viewer) - (half_extent - u_w - 1.0)) / u_w, 0.0, 1.0);
    a = max(a, clamp((u_w - d) / u_w, 0.0, 1.0));
  } else if (u_transitions == 1) {
    a = vec2(d.x == 0.0 ? 1.0 : 0.0, d.y == 0.0 ? 1.0 : 0.0);
  } else {
    a = vec2(0.0);
  }
  float alpha = max(a.x, a.y);
  precise float z = (1.0 - alpha) * zf + alpha * zc;
  v_grid = g;
  v_alpha = alpha;
  v_height = z;
  v_world = vec3(g * u_g, z);
  gl_Position = u_mvp * vec4(g * u_g, z, 1.0);
}
)";

const char* const kTerrainFragmentShader = R"(#version 450 core
in vec2 v_grid;
in float v_alpha;
in float v_height;
in vec3 v_world;
uniform sampler2DArray u_normal;  // 2n x 2n: dz/dx, dz/dy; linear filtering, repeat = toroidal wrap
uniform int u_level;
uniform int u_coarse_layer;
uniform float u_coarse_scale;    // 0.5: the coarser level's grid, 1: level 0 (no coarser level)
uniform int u_n;
uniform vec3 u_light;
uniform int u_flat;
uniform vec3 u_flat_rgb;
uniform vec2 u_zrange;
uniform int u_shading;           // 0: relative z ramp (the look before issue 19), 1: hypsometric
uniform vec3 u_eye;              // camera, metres
uniform vec3 u_haze_rgb;         // the sky at the horizon
uniform float u_haze_distance;   // metres at which 1 - 1/e of the haze is reached; 0: none
uniform float u_haze_max;
uniform int u_level_colours;     // tint each level (viewer toggle)
uniform vec3 u_hillshade_light;  // hypsometric: towards the sun
uniform float u_relief;          // hypsometric: slope exaggeration of the hillshade
uniform int u_drape;             // hypsometric: colours from the draped image where it covers
uniform vec4 u_drape_rect;       // its world x0, y0 (metres) and 1 / its width, 1 / its height
uniform sampler2D u_drape_image;
out vec4 o_colour;

vec3 ramp(float t) {
  const vec3 c0 = vec3(0.20, 0.45, 0.20), c1 = vec3(0.55, 0.60, 0.30), c2 = vec3(0.50, 0.40, 0.30),
             c3 = vec3(0.95, 0.95, 0.97);
  if (t < 0.33) return mix(c0, c1, t / 0.33);
  if (t < 0.75) return mix(c1, c2, (t - 0.33) / 0.42);
  return mix(c2, c3, (t - 0.75) / 0.25);
}

// Hypsometric tints by absolute height in metres (a map's layer colours): water at or below 0 m
// from light to deep blue, then lowland greens, tan uplands, brown mountains, grey rock, snow.
vec3 hypsometric(float h) {
  if (h <= 0.0) return mix(vec3(0.36, 0.58, 0.82), vec3(0.08, 0.20, 0.48), clamp(-h / 1000.0, 0.0, 1.0));
  const float z[8] = float[8](0.0, 300.0, 800.0, 1300.0, 1900.0, 2600.0, 3200.0, 4000.0);
  const vec3 c[8] = vec3[8](vec3(0.30, 0.52, 0.28), vec3(0.40, 0.60, 0.32), vec3(0.58, 0.66, 0.38),
                            vec3(0.76, 0.72, 0.48), vec3(0.68, 0.55, 0.40), vec3(0.60, 0.55, 0.52),
                            vec3(0.86, 0.86, 0.87), vec3(0.98, 0.98, 1.00));
  for (int i = 1; i < 8; ++i)
    if (h < z[i]) return mix(c[i - 1], c[i], (h - z[i - 1]) / (z[i] - z[i - 1]));
  return c[7];
}

vec3 level_tint(int l) {
  const vec3 t[6] = vec3[6](vec3(1.0, 0.45, 0.45), vec3(0.45, 1.0, 0.45), vec3(0.45, 0.55, 1.0),
                            vec3(1.0, 1.0, 0.4), vec3(1.0, 0.45, 1.0), vec3(0.4, 1.0, 1.0));
  return t[l % 6];
}

void main() {
  if (u_flat != 0) {
    o_colour = vec4(u_flat_rgb, 1.0);
    return;
  }
  // Texel T of the normal map sits at level position T / 2: position p is texture coordinate (2 p + 0.5) / 2n.
  float n2 = 2.0 * float(u_n);
  vec2 sf = texture(u_normal, vec3((2.0 * v_grid + 0.5) / n2, float(u_level))).rg;
  vec2 s = sf;
  if (v_alpha > 0.0) {  // only the transition band needs the coarser level's normal
    vec2 sc = texture(u_normal, vec3((2.0 * u_coarse_scale * v_grid + 0.5) / n2, float(u_coarse_layer))).rg;
    s = mix(sf, sc, v_alpha);
  }
  vec3 normal = normalize(vec3(-s, 1.0));
  float diffuse = max(dot(normal, normalize(u_light)), 0.0);
  vec3 colour;
  if (u_shading == 0) {
    float t = clamp((v_height - u_zrange.x) / max(u_zrange.y - u_zrange.x, 1e-3), 0.0, 1.0);
    colour = ramp(t) * (0.25 + 0.75 * diffuse);
  } else {
    // Hillshade: the normal map's slope lit from the north-west (u_light), as on a relief map;
    // water stays flat-lit.
    vec3 tint = hypsometric(v_height);
    vec3 relief = normalize(vec3(-u_relief * s, 1.0));
    float hill = max(dot(relief, normalize(u_hillshade_light)), 0.0);
    float shade = v_height <= 0.0 ? 0.85 : 0.22 + 0.95 * hill;
    if (u_drape != 0) {
      vec2 uv = (v_world.xy - u_drape_rect.xy) * u_drape_rect.zw;
      if (all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)))) {
        vec4 d = texture(u_drape_image, uv);
        tint = mix(tint, d.rgb, d.a);  // transparent pixels keep the height tint
        shade = mix(shade, 0.45 + 0.6 * hill, d.a);  // an image has its own shadows: a milder hillshade
      }
    }
    colour = tint * shade;
  }
  if (u_level_colours != 0) colour *= level_tint(u_level);
  if (u_haze_distance > 0.0) {
    float haze = u_haze_max * (1.0 - exp(-length(v_world - u_eye) / u_haze_distance));
    colour = mix(colour, u_haze_rgb, haze);
  }
  o_colour = vec4(colour, 1.0);
}
)";

}  // namespace internal

namespace {

using namespace internal;

// The footprints' vertex shader: a footprint vertex translated (and for strips transposed) into the
// level, clamped to the piece's extent.
const char* const kFootprintVertexHead = R"(#version 450 core
layout(location = 0) in ivec2 a_local;  // footprint vertex (constant vertex buffer), local grid units
uniform ivec2 u_origin;      // where the footprint's (0, 0) goes, level grid
uniform ivec2 u_extent;      // local coordinates are clamped to this: a cropped piece's extra
                             // quads collapse onto its edge (zero area, never rasterised)
uniform int u_transpose;     // 1: swap the footprint's axes (fix-ups, trims, stitches along x or y)
)";
const char* const kFootprintVertexMain = R"(
void main() {
  ivec2 p = u_transpose != 0 ? a_local.yx : a_local;
  clipmap_vertex(2 * (u_origin + min(p, u_extent)));
}
)";

// The sky behind the terrain: one full-screen triangle, coloured by the elevation of each pixel's
// view ray (horizon colour below the horizon, where only the distant haze is).
const char* kSkyVertexShader = R"(#version 450 core
out vec2 v_ndc;
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));
  v_ndc = p;
  gl_Position = vec4(p, 1.0, 1.0);
}
)";

const char* kSkyFragmentShader = R"(#version 450 core
in vec2 v_ndc;
uniform vec3 u_forward, u_right, u_up;  // camera basis, world frame
uniform vec2 u_tan_half;                // tan of half the horizontal and vertical field of view
uniform vec3 u_zenith_rgb, u_horizon_rgb;
out vec4 o_colour;
void main() {
  vec3 d = normalize(u_forward + v_ndc.x * u_tan_half.x * u_right + v_ndc.y * u_tan_half.y * u_up);
  float e = clamp(d.z, 0.0, 1.0);
  o_colour = vec4(mix(u_horizon_rgb, u_zenith_rgb, pow(e, 0.6)), 1.0);
}
)";

// Throws with the info log when a shader's compile or a program's link status is false.
template <typename GetIv, typename GetLog>
void check_status(GLuint object, GLenum status, GetIv get_iv, GetLog get_log, const char* what) {
  GLint ok = 0;
  get_iv(object, status, &ok);
  if (ok) return;
  char log[4096];
  get_log(object, GLsizei(sizeof log), nullptr, log);
  throw std::runtime_error(std::string("clipmap renderer: ") + what + " failed: " + log);
}

}  // namespace

GLuint internal::link(const std::vector<Stage>& stages) {
  const GLuint program = glCreateProgram();
  for (const Stage& st : stages) {
    const GLuint sh = glCreateShader(st.kind);
    glShaderSource(sh, GLsizei(st.sources.size()), st.sources.data(), nullptr);
    glCompileShader(sh);
    try {
      check_status(sh, GL_COMPILE_STATUS, glGetShaderiv, glGetShaderInfoLog, "shader compile");
    } catch (...) {
      glDeleteShader(sh);
      glDeleteProgram(program);
      throw;
    }
    glAttachShader(program, sh);
    glDeleteShader(sh);  // freed with the program
  }
  glLinkProgram(program);
  try {
    check_status(program, GL_LINK_STATUS, glGetProgramiv, glGetProgramInfoLog, "program link");
  } catch (...) {
    glDeleteProgram(program);
    throw;
  }
  return program;
}

void internal::check_gl(const char* step) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) {
    char code[16];
    std::snprintf(code, sizeof code, "0x%04X", unsigned(e));
    throw std::runtime_error(std::string("clipmap renderer: OpenGL error ") + code + " in " + step);
  }
}

internal::TerrainUniforms::TerrainUniforms(GLuint program) {
  auto loc = [&](const char* name) { return glGetUniformLocation(program, name); };
  level = loc("u_level"), n = loc("u_n"), wrap_base = loc("u_wrap_base"), g = loc("u_g");
  viewer = loc("u_viewer"), active = loc("u_active"), w = loc("u_w"), transitions = loc("u_transitions");
  mvp = loc("u_mvp"), coarse_layer = loc("u_coarse_layer"), coarse_scale = loc("u_coarse_scale");
  light = loc("u_light"), flat = loc("u_flat"), flat_rgb = loc("u_flat_rgb"), zrange = loc("u_zrange");
  shading = loc("u_shading"), eye = loc("u_eye"), haze_rgb = loc("u_haze_rgb");
  haze_distance = loc("u_haze_distance"), haze_max = loc("u_haze_max");
  level_colours = loc("u_level_colours");
  hillshade_light = loc("u_hillshade_light"), relief = loc("u_relief");
  drape = loc("u_drape"), drape_rect = loc("u_drape_rect");
  glUseProgram(program);
  glUniform1i(loc("u_z"), 0);
  glUniform1i(loc("u_zc"), 1);
  glUniform1i(loc("u_normal"), 2);
  glUniform1i(loc("u_drape_image"), 3);
}

namespace {

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

// The camera's forward, right and up vectors in the world frame.
void camera_basis(const Camera& cam, double f[3], double r[3], double u[3]) {
  const double cp = std::cos(cam.pitch), sp = std::sin(cam.pitch), cy = std::cos(cam.yaw),
               sy = std::sin(cam.yaw);
  f[0] = cp * cy, f[1] = cp * sy, f[2] = sp;
  // right = f x up(0,0,1), normalised; up' = right x f
  r[0] = f[1], r[1] = -f[0], r[2] = 0;
  const double rl = std::hypot(r[0], r[1]);
  if (rl < 1e-9)
    r[0] = 1, r[1] = 0;  // looking straight up or down: any right vector will do
  else
    r[0] /= rl, r[1] /= rl;
  u[0] = r[1] * f[2] - r[2] * f[1], u[1] = r[2] * f[0] - r[0] * f[2], u[2] = r[0] * f[1] - r[1] * f[0];
}

Mat4 view_projection(const Camera& cam, double aspect, double near_m, double far_m) {
  double f[3], r[3], u[3];
  camera_basis(cam, f, r, u);
  const double* e = cam.position;
  Mat4 view{r[0],
            u[0],
            -f[0],
            0,
            r[1],
            u[1],
            -f[1],
            0,
            r[2],
            u[2],
            -f[2],
            0,
            -(r[0] * e[0] + r[1] * e[1] + r[2] * e[2]),
            -(u[0] * e[0] + u[1] * e[1] + u[2] * e[2]),
            (f[0] * e[0] + f[1] * e[1] + f[2] * e[2]),
            1};
  const double t = 1.0 / std::tan(cam.fov_y_deg * M_PI / 360.0);
  Mat4 proj{t / aspect,
            0,
            0,
            0,
            0,
            t,
            0,
            0,
            0,
            0,
            (far_m + near_m) / (near_m - far_m),
            -1,
            0,
            0,
            2 * far_m * near_m / (near_m - far_m),
            0};
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

bool contains(const Rect& outer, const Rect& inner) {
  return inner.x0 >= outer.x0 && inner.y0 >= outer.y0 && inner.x0 + inner.width <= outer.x0 + outer.width &&
         inner.y0 + inner.height <= outer.y0 + outer.height;
}

// Whether `dirty` (the clipmap's last update) holds every sample a level gained since the textures
// showed clip region `before`: the exposed columns (whole height) and rows, as the refill writes them.
// False when an update that moved the level was never uploaded: its samples are only in the clipmap.
bool dirty_covers_move(const Rect& before, const Rect& now, const std::vector<Rect>& dirty) {
  const int64_t n = now.width, dx = now.x0 - before.x0, dy = now.y0 - before.y0;
  std::vector<Rect> gained;
  if (std::abs(dx) >= n || std::abs(dy) >= n) {
    gained.push_back(now);
  } else {
    if (dx != 0) gained.push_back(Rect{dx > 0 ? before.x0 + n : now.x0, now.y0, std::abs(dx), n});
    if (dy != 0)
      gained.push_back(
          Rect{std::max(now.x0, before.x0), dy > 0 ? before.y0 + n : now.y0, n - std::abs(dx), std::abs(dy)});
  }
  for (const Rect& g : gained)
    if (std::none_of(dirty.begin(), dirty.end(), [&](const Rect& d) { return contains(d, g); })) return false;
  return true;
}

}  // namespace

struct ClipmapRenderer::Gl {
  GLuint program = 0, vao = 0, fbo = 0, colour = 0, depth = 0;
  GLuint tex_z = 0, tex_zc = 0, tex_normal = 0, vbo = 0, ibo = 0;
  // The constant footprints (L&H 2004 §6.1, A&H 2005 §2.3.2) in one vertex and one index buffer.
  struct Footprint {
    GLint base_vertex = 0;
    size_t first_index = 0;
    int row_indices = 0;  // indices per local row of quads (row-major: the first k rows are a prefix)
    int rows = 0;         // local rows of quads
    int cols = 0;         // local columns of quads
  };
  Footprint block, fixup, trim, stitch;
  // Per level: the clip region the textures hold (valid once uploaded), so that an update whose
  // dirty rectangles never reached upload() is noticed and the level sent whole.
  std::vector<Rect> uploaded_clip;
  std::vector<bool> uploaded;
  TerrainUniforms u;  // the footprints' program
  GLint u_origin = -1, u_extent = -1, u_transpose = -1;
  // The tessellation mesh, made on the first frame that asks for it.
  std::unique_ptr<TessellationMesh> tessellation;
  GLuint timer = 0, primitives = 0;  // GL_TIME_ELAPSED, GL_PRIMITIVES_GENERATED queries
  // The draped image (set_drape): an RGBA8 texture with mipmaps and the world rectangle it covers.
  GLuint drape = 0;
  double drape_rect[4] = {0, 0, 0, 0};
  // The sky gradient (hypsometric shading): a full-screen triangle drawn before the terrain.
  GLuint sky_program = 0, sky_vao = 0;
  GLint s_forward = -1, s_right = -1, s_up = -1, s_tan_half = -1, s_zenith = -1, s_horizon = -1;
};

ClipmapRenderer::ClipmapRenderer(int n, int levels, int width, int height)
    : gl_(std::make_unique<Gl>()), n_(n), levels_(levels), width_(width), height_(height) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    throw std::invalid_argument("clipmap renderer: frame size must be 1..16384 pixels a side");
  Gl& g = *gl_;
  g.uploaded_clip.assign(size_t(levels), Rect{});
  g.uploaded.assign(size_t(levels), false);
  g.program = link({{GL_VERTEX_SHADER, {kFootprintVertexHead, kClipmapVertexGlsl, kFootprintVertexMain}},
                    {GL_FRAGMENT_SHADER, {kTerrainFragmentShader}}});
  g.sky_program = link({{GL_VERTEX_SHADER, {kSkyVertexShader}}, {GL_FRAGMENT_SHADER, {kSkyFragmentShader}}});
  glCreateQueries(GL_TIME_ELAPSED, 1, &g.timer);
  glCreateQueries(GL_PRIMITIVES_GENERATED, 1, &g.primitives);
  glCreateVertexArrays(1, &g.sky_vao);
  auto sloc = [&](const char* name) { return glGetUniformLocation(g.sky_program, name); };
  g.s_forward = sloc("u_forward"), g.s_right = sloc("u_right"), g.s_up = sloc("u_up");
  g.s_tan_half = sloc("u_tan_half"), g.s_zenith = sloc("u_zenith_rgb"), g.s_horizon = sloc("u_horizon_rgb");
  g.u = TerrainUniforms(g.program);
  g.u_origin = glGetUniformLocation(g.program, "u_origin");
  g.u_extent = glGetUniformLocation(g.program, "u_extent");
  g.u_transpose = glGetUniformLocation(g.program, "u_transpose");

  // Footprints, local coordinates as short2: m x m block (m = (n+1)/4), the 3 x m fix-up (2 quads
  // wide), the 2 x n trim (1 quad wide, up to a ring side long) and the line of zero-area stitching
  // triangles (v_2k, v_2k+1, v_2k+2) that closes the T-junctions on a ring's outer edge. Every quad
  // is split along its (0,0)-(1,1) diagonal, the one the clipmap's zc assumes; transposing keeps it.
  std::vector<int16_t> vertices;
  std::vector<uint16_t> indices;
  auto grid = [&](int cols, int rows, Gl::Footprint& f) {  // cols x rows quads
    f.base_vertex = GLint(vertices.size() / 2);
    f.first_index = indices.size();
    f.row_indices = 6 * cols;
    f.rows = rows;
    f.cols = cols;
    for (int y = 0; y <= rows; ++y)
      for (int x = 0; x <= cols; ++x) vertices.push_back(int16_t(x)), vertices.push_back(int16_t(y));
    const int w = cols + 1;
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        const int v = y * w + x;
        for (int k : {v, v + 1, v + w + 1, v, v + w + 1, v + w}) indices.push_back(uint16_t(k));
      }
  };
  const int m = (n + 1) / 4;
  grid(m - 1, m - 1, g.block);
  grid(2, m - 1, g.fixup);
  grid(1, n - 1, g.trim);
  g.stitch.base_vertex = GLint(vertices.size() / 2);
  g.stitch.first_index = indices.size();
  g.stitch.row_indices = 3;
  g.stitch.rows = (n - 1) / 2;
  g.stitch.cols = 0;
  for (int i = 0; i < n; ++i) vertices.push_back(int16_t(i)), vertices.push_back(0);
  for (int t = 0; t < (n - 1) / 2; ++t)
    for (int k = 0; k < 3; ++k) indices.push_back(uint16_t(2 * t + k));
  glCreateBuffers(1, &g.vbo);
  glNamedBufferStorage(g.vbo, GLsizeiptr(vertices.size() * sizeof(int16_t)), vertices.data(), 0);
  glCreateBuffers(1, &g.ibo);
  glNamedBufferStorage(g.ibo, GLsizeiptr(indices.size() * sizeof(uint16_t)), indices.data(), 0);
  glCreateVertexArrays(1, &g.vao);
  glEnableVertexArrayAttrib(g.vao, 0);
  glVertexArrayAttribIFormat(g.vao, 0, 2, GL_SHORT, 0);
  glVertexArrayAttribBinding(g.vao, 0, 0);
  glVertexArrayVertexBuffer(g.vao, 0, g.vbo, 0, 2 * sizeof(int16_t));
  glVertexArrayElementBuffer(g.vao, g.ibo);

  auto make_array = [&](GLuint& tex, GLenum format, bool linear, int side) {
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &tex);
    glTextureStorage3D(tex, 1, format, side, side, levels);
    glTextureParameteri(tex, GL_TEXTURE_MIN_FILTER, linear ? GL_LINEAR : GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_MAG_FILTER, linear ? GL_LINEAR : GL_NEAREST);
    glTextureParameteri(tex, GL_TEXTURE_WRAP_S, GL_REPEAT);  // repeat = the toroidal wrap
    glTextureParameteri(tex, GL_TEXTURE_WRAP_T, GL_REPEAT);
  };
  make_array(g.tex_z, GL_R32F, false, n);
  make_array(g.tex_zc, GL_R32F, false, n);
  make_array(g.tex_normal, GL_RG32F, true, 2 * n);

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
  const GLuint textures[3] = {g.tex_z, g.tex_zc, g.tex_normal};
  glDeleteTextures(3, textures);
  glDeleteBuffers(1, &g.vbo);
  glDeleteBuffers(1, &g.ibo);
  glDeleteFramebuffers(1, &g.fbo);
  glDeleteRenderbuffers(1, &g.colour);
  glDeleteRenderbuffers(1, &g.depth);
  glDeleteVertexArrays(1, &g.vao);
  glDeleteVertexArrays(1, &g.sky_vao);
  glDeleteProgram(g.program);
  glDeleteProgram(g.sky_program);
  glDeleteQueries(1, &g.timer);
  glDeleteQueries(1, &g.primitives);
  g.tessellation.reset();
  if (g.drape) glDeleteTextures(1, &g.drape);
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
    const Rect clip = cm.clip_region(l);
    // Several updates between two uploads (or another clipmap) leave samples the last update's
    // dirty rectangles do not name: the textures would keep stale heights that the culling bounds,
    // taken from the clipmap, no longer describe. Such a level is uploaded whole.
    const bool stale = !g.uploaded[size_t(l)] || !dirty_covers_move(g.uploaded_clip[size_t(l)], clip, *rects);
    if (everything || stale) {
      all.push_back(clip);
      rects = &all;
    }
    g.uploaded[size_t(l)] = true;
    g.uploaded_clip[size_t(l)] = clip;
    for (const Rect& r : *rects) {
      // A rectangle of the level maps to up to 2 x 2 pieces of the toroidal texture.
      const int64_t tx = cm.wrap(r.x0), ty = cm.wrap(r.y0);
      const int64_t wx[2] = {std::min<int64_t>(r.width, n_ - tx),
                             r.width - std::min<int64_t>(r.width, n_ - tx)};
      const int64_t wy[2] = {std::min<int64_t>(r.height, n_ - ty),
                             r.height - std::min<int64_t>(r.height, n_ - ty)};
      for (int py = 0; py < 2; ++py)
        for (int px = 0; px < 2; ++px) {
          if (wx[px] <= 0 || wy[py] <= 0) continue;
          const int64_t ox = px == 0 ? tx : 0, oy = py == 0 ? ty : 0;
          const size_t at = size_t(oy * n_ + ox);
          glTextureSubImage3D(g.tex_z, 0, GLint(ox), GLint(oy), l, GLsizei(wx[px]), GLsizei(wy[py]), 1,
                              GL_RED, GL_FLOAT, cm.heights(l) + at);
          glTextureSubImage3D(g.tex_zc, 0, GLint(ox), GLint(oy), l, GLsizei(wx[px]), GLsizei(wy[py]), 1,
                              GL_RED, GL_FLOAT, cm.coarse_heights(l) + at);
          upload_samples_ += wx[px] * wy[py];
          // The normal map's texels of these samples: the same piece at twice the resolution.
          glPixelStorei(GL_UNPACK_ROW_LENGTH, 2 * n_);
          glTextureSubImage3D(g.tex_normal, 0, GLint(2 * ox), GLint(2 * oy), l, GLsizei(2 * wx[px]),
                              GLsizei(2 * wy[py]), 1, GL_RG, GL_FLOAT,
                              cm.normal_map(l) + 2 * size_t(2 * oy * 2 * n_ + 2 * ox));
          glPixelStorei(GL_UNPACK_ROW_LENGTH, n_);
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
  glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
  const bool hypsometric = opt.shading == Shading::Hypsometric && !opt.flat_colour;
  if (hypsometric) {  // the sky gradient, behind everything (no depth written)
    double f[3], r[3], u[3];
    camera_basis(cam, f, r, u);
    const double ty = std::tan(cam.fov_y_deg * M_PI / 360.0), tx = ty * double(width_) / double(height_);
    glDisable(GL_DEPTH_TEST);
    glDepthMask(GL_FALSE);
    glUseProgram(g.sky_program);
    glUniform3f(g.s_forward, float(f[0]), float(f[1]), float(f[2]));
    glUniform3f(g.s_right, float(r[0]), float(r[1]), float(r[2]));
    glUniform3f(g.s_up, float(u[0]), float(u[1]), float(u[2]));
    glUniform2f(g.s_tan_half, float(tx), float(ty));
    glUniform3f(g.s_zenith, opt.sky_zenith_rgb[0], opt.sky_zenith_rgb[1], opt.sky_zenith_rgb[2]);
    glUniform3f(g.s_horizon, opt.sky_horizon_rgb[0], opt.sky_horizon_rgb[1], opt.sky_horizon_rgb[2]);
    glBindVertexArray(g.sky_vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glDepthMask(GL_TRUE);
  }
  if (opt.wireframe) glPolygonMode(GL_FRONT_AND_BACK, GL_LINE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDisable(GL_CULL_FACE);  // stitching triangles have no meaningful orientation
  const bool tessellate = opt.mesh == Mesh::Tessellation;
  if (tessellate && !g.tessellation) g.tessellation = std::make_unique<TessellationMesh>();
  const TerrainUniforms& u = tessellate ? g.tessellation->uniforms() : g.u;
  glUseProgram(tessellate ? g.tessellation->program() : g.program);
  glBindVertexArray(g.vao);
  glBindTextureUnit(0, g.tex_z);
  glBindTextureUnit(1, g.tex_zc);
  glBindTextureUnit(2, g.tex_normal);
  glUniformMatrix4fv(u.mvp, 1, GL_FALSE, mvp);
  glUniform1i(u.n, n_);
  glUniform1i(u.transitions, opt.transitions ? 2 : opt.snap_perimeter ? 1 : 0);
  glUniform3f(u.light, opt.light_dir[0], opt.light_dir[1], opt.light_dir[2]);
  glUniform1i(u.flat, opt.flat_colour ? 1 : 0);
  glUniform3f(u.flat_rgb, opt.terrain_rgb[0], opt.terrain_rgb[1], opt.terrain_rgb[2]);
  glUniform1i(u.shading, hypsometric ? 1 : 0);
  glUniform1i(u.level_colours, opt.level_colours ? 1 : 0);
  glUniform3f(u.eye, float(cam.position[0]), float(cam.position[1]), float(cam.position[2]));
  glUniform3f(u.haze_rgb, opt.sky_horizon_rgb[0], opt.sky_horizon_rgb[1], opt.sky_horizon_rgb[2]);
  // Haze: 1 - 1/e of haze_max at half the coarsest level's extent unless given (scales with the scene).
  const double haze_m = opt.haze_distance_m > 0 ? opt.haze_distance_m : 0.5 * n_ * cm.spacing(0);
  glUniform1f(u.haze_distance, hypsometric && opt.haze_max > 0 ? float(haze_m) : 0.0f);
  glUniform1f(u.haze_max, opt.haze_max);
  glUniform3f(u.hillshade_light, opt.hillshade_dir[0], opt.hillshade_dir[1], opt.hillshade_dir[2]);
  glUniform1f(u.relief, opt.relief);
  const bool drape = opt.drape && g.drape != 0;
  glUniform1i(u.drape, drape ? 1 : 0);
  if (drape) {
    glBindTextureUnit(3, g.drape);
    glUniform4f(u.drape_rect, float(g.drape_rect[0]), float(g.drape_rect[1]), float(1 / g.drape_rect[2]),
                float(1 / g.drape_rect[3]));
  }
  if (opt.z_hi > opt.z_lo) {
    glUniform2f(u.zrange, opt.z_lo, opt.z_hi);
  } else {
    const ZRange zr = cm.z_bounds(0, cm.active_region(0));
    glUniform2f(u.zrange, zr.lo, zr.hi);
  }

  const int64_t B = g.block.cols;  // quads per side of the m x m block
  glBeginQuery(GL_TIME_ELAPSED, g.timer);
  if (tessellate) glBeginQuery(GL_PRIMITIVES_GENERATED, g.primitives);
  // One footprint instance: local (0,0) at `origin`, clamped to extent (ex, ey) quads in world axes;
  // only the local rows that hold visible quads are submitted.
  auto draw = [&](const Gl::Footprint& f, int64_t ox, int64_t oy, int64_t ex, int64_t ey, bool transpose) {
    const int64_t local_rows = std::min<int64_t>(transpose ? ex : ey, f.rows);
    glUniform2i(g.u_origin, GLint(ox), GLint(oy));
    glUniform2i(g.u_extent, GLint(ex), GLint(ey));
    glUniform1i(g.u_transpose, transpose ? 1 : 0);
    glDrawElementsBaseVertex(GL_TRIANGLES, GLsizei(local_rows * f.row_indices), GL_UNSIGNED_SHORT,
                             reinterpret_cast<const void*>(f.first_index * sizeof(uint16_t)), f.base_vertex);
    ++stats.draw_calls;
  };
  // Fine to coarse, so that nearer terrain fills the depth buffer first.
  for (int l = levels_ - 1; l >= 0; --l) {
    const LevelRegion a = cm.active_region(l);
    if (a.empty()) continue;
    ++stats.levels_drawn;
    const double gm = cm.spacing(l);
    const auto v = cm.viewer_grid(l);
    const Rect clip = cm.clip_region(l);
    const GLint base_x = GLint(n_ * (std::abs(clip.x0) / n_ + 2)),
                base_y = GLint(n_ * (std::abs(clip.y0) / n_ + 2));
    glUniform1i(u.level, l);
    glUniform2i(u.wrap_base, base_x, base_y);
    glUniform1f(u.g, float(gm));
    glUniform2f(u.viewer, float(v[0]), float(v[1]));
    glUniform4i(u.active, GLint(a.x0), GLint(a.y0), GLint(a.x1), GLint(a.y1));
    glUniform1f(u.w, float(cm.transition_width(l)));
    glUniform1i(u.coarse_layer, l > 0 ? l - 1 : 0);
    glUniform1f(u.coarse_scale, l > 0 ? 0.5f : 1.0f);

    // A piece of the render region (x0..x1, y0..y1 vertices), culled against its extruded z range.
    auto visible = [&](int64_t x0, int64_t y0, int64_t x1, int64_t y1) {
      if (!opt.culling) return true;
      const ZRange zr = cm.z_bounds(l, LevelRegion{x0, y0, x1, y1});
      const double lo[3] = {double(x0) * gm, double(y0) * gm, double(zr.lo)};
      const double hi[3] = {double(x1) * gm, double(y1) * gm, double(zr.hi)};
      if (!box_outside(planes, lo, hi)) return true;
      ++stats.blocks_culled;
      return false;
    };
    // A strip 1 or 2 quads wide: trims or fix-ups laid end to end along it.
    auto strip = [&](int64_t x0, int64_t y0, int64_t x1, int64_t y1) {
      const bool along_x = (x1 - x0) > (y1 - y0);
      const int64_t width = along_x ? y1 - y0 : x1 - x0, length = along_x ? x1 - x0 : y1 - y0;
      const Gl::Footprint& f = width == 1 ? g.trim : g.fixup;
      for (int64_t s = 0; s < length; s += f.rows) {
        const int64_t len = std::min<int64_t>(f.rows, length - s);
        const int64_t px = along_x ? x0 + s : x0, py = along_x ? y0 : y0 + s;
        const int64_t ex = along_x ? len : width, ey = along_x ? width : len;
        if (!visible(px, py, px + ex, py + ey)) continue;
        draw(f, px, py, ex, ey, along_x);
        ++stats.blocks_drawn;
        stats.triangles += 2 * ex * ey;
      }
    };
    // A rectangle of the render region: m x m blocks (the last ones clamped), a 1-2 quad remainder
    // on the right and bottom as fix-up / trim strips (the paper's ring fix-ups and L-shaped trim).
    auto tile = [&](const LevelRegion& p) {
      const int64_t W = p.x1 - p.x0, H = p.y1 - p.y0;
      if (W <= 0 || H <= 0) return;
      if (W <= 2 || H <= 2) return strip(p.x0, p.y0, p.x1, p.y1);
      const int64_t rw = W % B <= 2 ? W % B : 0, rh = H % B <= 2 ? H % B : 0;
      const int64_t mx1 = p.x1 - rw, my1 = p.y1 - rh;
      for (int64_t by = p.y0; by < my1; by += B)
        for (int64_t bx = p.x0; bx < mx1; bx += B) {
          const int64_t w = std::min<int64_t>(B, mx1 - bx), h = std::min<int64_t>(B, my1 - by);
          if (!visible(bx, by, bx + w, by + h)) continue;
          draw(g.block, bx, by, w, h, false);
          ++stats.blocks_drawn;
          stats.triangles += 2 * w * h;
        }
      if (rw > 0) strip(mx1, p.y0, p.x1, my1);
      if (rh > 0) strip(p.x0, my1, p.x1, p.y1);
    };

    // render region = active(l) - active(l+1), as up to four rectangles.
    LevelRegion inner;
    if (l + 1 < levels_ && !cm.active_region(l + 1).empty()) {
      const LevelRegion f = cm.active_region(l + 1);
      inner = LevelRegion{f.x0 / 2, f.y0 / 2, f.x1 / 2, f.y1 / 2};
    }
    if (tessellate) {
      stats.patches += g.tessellation->draw_level(
          a, inner, opt.stitch, [&](const LevelRegion& p) { return visible(p.x0, p.y0, p.x1, p.y1); },
          stats.blocks_drawn);
      ++stats.draw_calls;
      glBindVertexArray(g.vao);
    } else if (inner.empty()) {
      tile(a);
    } else {
      tile(LevelRegion{a.x0, a.y0, a.x1, inner.y0});
      tile(LevelRegion{a.x0, inner.y1, a.x1, a.y1});
      tile(LevelRegion{a.x0, inner.y0, inner.x0, inner.y1});
      tile(LevelRegion{inner.x1, inner.y0, a.x1, inner.y1});
    }
    // Zero-area triangles (v0, v1, v2) on each outer side close the T-junctions against level l-1.
    if (opt.stitch && l > 0 && !tessellate) {
      const int64_t wx = a.x1 - a.x0, wy = a.y1 - a.y0;
      const struct {
        int64_t x, y, len;
        bool along_x;
      } sides[4] = {
          {a.x0, a.y0, wx, true}, {a.x0, a.y1, wx, true}, {a.x0, a.y0, wy, false}, {a.x1, a.y0, wy, false}};
      for (const auto& sd : sides) {
        // The stitch line is local x with one row of triangles per 2 quads: extent (len, 0).
        const int64_t tris = sd.len / 2;
        glUniform2i(g.u_origin, GLint(sd.x), GLint(sd.y));
        glUniform2i(g.u_extent, GLint(sd.along_x ? sd.len : 0), GLint(sd.along_x ? 0 : sd.len));
        glUniform1i(g.u_transpose, sd.along_x ? 0 : 1);
        glDrawElementsBaseVertex(GL_TRIANGLES, GLsizei(tris * 3), GL_UNSIGNED_SHORT,
                                 reinterpret_cast<const void*>(g.stitch.first_index * sizeof(uint16_t)),
                                 g.stitch.base_vertex);
        ++stats.draw_calls;
        stats.triangles += tris;
      }
    }
  }
  glEndQuery(GL_TIME_ELAPSED);
  if (tessellate) glEndQuery(GL_PRIMITIVES_GENERATED);
  glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
  stats.seconds_submit = since(t0);
  glFinish();
  GLuint64 gpu_ns = 0;
  glGetQueryObjectui64v(g.timer, GL_QUERY_RESULT, &gpu_ns);
  stats.seconds_gpu = double(gpu_ns) * 1e-9;
  if (tessellate) {
    GLuint64 generated = 0;
    glGetQueryObjectui64v(g.primitives, GL_QUERY_RESULT, &generated);
    stats.triangles = int64_t(generated);
  }
  check_gl("render");
  stats.seconds_render = since(t0);
  return stats;
}

void ClipmapRenderer::set_drape(const std::vector<uint8_t>& rgba, int width, int height, double x0_m,
                                double y0_m, double width_m, double height_m) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384 ||
      rgba.size() != size_t(width) * size_t(height) * 4 || !(width_m > 0) || !(height_m > 0))
    throw std::invalid_argument(
        "clipmap renderer: drape image must be 1..16384 pixels a side, RGBA8, over a "
        "positive area");
  Gl& g = *gl_;
  if (g.drape) glDeleteTextures(1, &g.drape);
  int mip_levels = 1;
  while ((std::max(width, height) >> mip_levels) > 0) ++mip_levels;
  glCreateTextures(GL_TEXTURE_2D, 1, &g.drape);
  glTextureStorage2D(g.drape, mip_levels, GL_RGBA8, width, height);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTextureSubImage2D(g.drape, 0, 0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  glGenerateTextureMipmap(g.drape);
  glTextureParameteri(g.drape, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTextureParameteri(g.drape, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(g.drape, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(g.drape, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  g.drape_rect[0] = x0_m, g.drape_rect[1] = y0_m, g.drape_rect[2] = width_m, g.drape_rect[3] = height_m;
  check_gl("drape upload");
}

void ClipmapRenderer::blit_to_default_framebuffer(int width, int height) const {
  glBlitNamedFramebuffer(gl_->fbo, 0, 0, 0, width_, height_, 0, 0, width, height, GL_COLOR_BUFFER_BIT,
                         width == width_ && height == height_ ? GL_NEAREST : GL_LINEAR);
  check_gl("blit");
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

}  // namespace terrain::render
