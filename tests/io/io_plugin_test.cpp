// The image plugin is loaded only when an image is read or written: with $TERRAIN_IMAGE_PLUGIN
// naming a file that does not exist, non-image work still succeeds, and image work fails with the
// documented status and a message naming the image, the plugin path and the loader's reason.
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "io_test_util.h"

TEST_CASE("the image plugin is loaded only for images, and a missing one is a clear error", "[io][plugin]") {
  iotest::TempDir dir;
  const std::string png = dir.file("grid.png"), raw = dir.file("grid.raw");
  // Written with the real plugin, before it is taken away.
  auto made =
      iotest::run_tools(dir, {{"terrain-synth", {"-o", png, "--width", "20", "--height", "10", "-q"}},
                              {"terrain-synth", {"-o", raw, "--width", "20", "--height", "10", "-q"}}});
  REQUIRE(made[0].status == 0);
  REQUIRE(made[1].status == 0);

  const std::string missing = dir.file("no-such-plugin.so");
  iotest::ScopedEnv env("TERRAIN_IMAGE_PLUGIN", missing);
  auto r = iotest::run_tools(
      dir, {{"terrain-info", {raw, "-q"}},
            {"terrain-info", {png, "-q"}},
            {"terrain-synth", {"-o", dir.file("out.png"), "--width", "5", "--height", "5", "-q"}}});
  CHECK(r[0].status == 0);
  INFO(r[1].err);
  CHECK(r[1].status == 6);
  CHECK(r[1].err.find(png) != std::string::npos);
  CHECK(r[1].err.find("cannot load the image plugin " + missing) != std::string::npos);
  CHECK(r[1].err.find("cannot open shared object file") != std::string::npos);  // dlerror()'s reason
  INFO(r[2].err);
  CHECK(r[2].status == 9);
  CHECK(r[2].err.find("out.png") != std::string::npos);
  CHECK(r[2].err.find("cannot load the image plugin " + missing) != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir.file("out.png")));
}

TEST_CASE("an installed tree, moved elsewhere, loads its own image plugin and serves find_package(terrain)",
          "[io][plugin][install]") {
  iotest::TempDir dir;
  const std::string png = dir.file("grid.png");
  REQUIRE(
      iotest::run_tool(dir, {"terrain-synth", {"-o", png, "--width", "20", "--height", "10", "-q"}}).status ==
      0);
  const std::string prefix = dir.file("inst"), moved = dir.file("moved");
  const std::string install = "cmake --install " + iotest::shell_quote(TERRAIN_BINARY_DIR) + " --prefix " +
                              iotest::shell_quote(prefix) + " >" +
                              iotest::shell_quote(dir.file("install.log")) + " 2>&1";
  REQUIRE(std::system(install.c_str()) == 0);
  std::filesystem::rename(prefix, moved);
  // glibc's loader names every object it maps; the plugin must come from the moved tree.
  const std::string run = "LD_DEBUG=files " + iotest::shell_quote(moved + "/bin/terrain-info") + " " +
                          iotest::shell_quote(png) + " -q >/dev/null 2>" +
                          iotest::shell_quote(dir.file("ld.log"));
  CHECK(std::system(run.c_str()) == 0);
  const auto log = iotest::read_file(dir.file("ld.log"));
  const std::string text(log.begin(), log.end());
  INFO(text.substr(0, 2000));
  // bin/../<libdir>/terrain/ (libdir is lib, or lib/<multiarch> for a /usr prefix).
  const size_t at = text.find("file=" + moved + "/");
  REQUIRE(at != std::string::npos);
  const std::string loaded = text.substr(at + 5, text.find_first_of(" \n", at) - at - 5);
  CHECK(loaded.size() > moved.size());
  CHECK(loaded.find("/terrain/libterrain_image_oiio.so") ==
        loaded.size() - std::string("/terrain/libterrain_image_oiio.so").size());

  // A program that embeds the libraries through the installed CMake package.
  const std::string project = dir.file("consumer");
  std::filesystem::create_directories(project);
  {
    std::ofstream cm(project + "/CMakeLists.txt");
    cm << "cmake_minimum_required(VERSION 3.22)\nproject(consumer CXX)\nset(CMAKE_CXX_STANDARD 20)\n"
          "find_package(terrain REQUIRED)\nadd_executable(consumer main.cpp)\n"
          "target_link_libraries(consumer PRIVATE terrain::runtime)\n";
    std::ofstream main(project + "/main.cpp");
    main << "#include <codec/codec.h>\n#include <readers/terrain_generator.h>\n"
            "#include <runtime/screen_error.h>\n"
            "int main() {\n"
            "  const terrain::Heightmap map = terrain::synthesize_terrain({.seed = 1, .width = 33, .height = "
            "17});\n"
            "  return map.width() == 33 && codec::encode_bound(33, 17, codec::EncodeOptions{}) > 0 &&\n"
            "         terrain::runtime::triangle_size_px(640, 480, 60, 255) > 0 ? 0 : 1;\n}\n";
  }
#ifdef TERRAIN_SANITIZED
  const std::string flags = std::string(" -DCMAKE_CXX_FLAGS=") + TERRAIN_SANITIZER_FLAGS;
#else
  const std::string flags;
#endif
  const std::string build = iotest::shell_quote(project + "/build");
  const std::string to_log = " >>" + iotest::shell_quote(dir.file("consumer.log")) + " 2>&1";
  const std::string configure = "cmake -S " + iotest::shell_quote(project) + " -B " + build +
                                " -DCMAKE_PREFIX_PATH=" + iotest::shell_quote(moved) + flags + to_log;
  const bool built =
      std::system(configure.c_str()) == 0 && std::system(("cmake --build " + build + to_log).c_str()) == 0;
  const auto consumer_log = iotest::read_file(dir.file("consumer.log"));
  INFO(std::string(consumer_log.begin(), consumer_log.end()).substr(0, 4000));
  REQUIRE(built);
  CHECK(std::system((build + "/consumer").c_str()) == 0);

  // The same program built with plain c++ and the installed pkg-config files.
#ifdef TERRAIN_SANITIZED
  const std::string cxx_flags = std::string(" ") + TERRAIN_SANITIZER_FLAGS;
#else
  const std::string cxx_flags;
#endif
  const std::string pc_path =
      "PKG_CONFIG_PATH=" + iotest::shell_quote(moved + "/" + TERRAIN_INSTALL_LIBDIR + "/pkgconfig");
  const std::string pc_exe = iotest::shell_quote(project + "/consumer_pc");
  const std::string compile = "c++ -std=c++20" + cxx_flags + " " +
                              iotest::shell_quote(project + "/main.cpp") + " -o " + pc_exe + " $(" + pc_path +
                              " pkg-config --cflags --libs terrain-runtime)" + to_log;
  const bool pc_built = std::system(compile.c_str()) == 0;
  const auto pc_log = iotest::read_file(dir.file("consumer.log"));
  INFO(std::string(pc_log.begin(), pc_log.end()).substr(0, 4000));
  REQUIRE(pc_built);
  CHECK(std::system(pc_exe.c_str()) == 0);
}
