// Locating ../shared/data for tests. In CI (CI=true) missing data is a failure, elsewhere a skip.
#pragma once
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace testdata {

inline std::filesystem::path shared_dir() {
  if (const char* env = std::getenv("TERRAIN_SHARED_DATA")) return env;
  return TERRAIN_SHARED_DATA;
}

inline bool in_ci() {
  const char* ci = std::getenv("CI");
  return ci && std::string(ci) == "true";
}

// Returns the path of a shared data file; FAILs in CI when it is missing, otherwise returns "" (callers
// SKIP).
inline std::string require(const std::string& name) {
  auto p = shared_dir() / name;
  if (std::filesystem::exists(p)) return p.string();
  if (in_ci()) FAIL("shared data file missing in CI: " << p.string());
  WARN("shared data file missing, test skipped: " << p.string());
  return {};
}

// Every DEM file in ../shared/data (sorted), failing in CI if the folder is absent.
inline std::vector<std::string> all_dems() {
  std::vector<std::string> out;
  auto dir = shared_dir();
  if (!std::filesystem::is_directory(dir)) {
    if (in_ci()) FAIL("shared data folder missing in CI: " << dir.string());
    WARN("shared data folder missing: " << dir.string());
    return out;
  }
  for (auto& e : std::filesystem::directory_iterator(dir)) {
    auto ext = e.path().extension().string();
    if (ext == ".hgt" || ext == ".png") out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// True in the ASan/UBSan build, which runs every test about ten times slower.
inline constexpr bool sanitized() {
#ifdef TERRAIN_SANITIZED
  return true;
#else
  return false;
#endif
}

// The DEMs for tests that build whole pyramids of each: all of them normally; under the sanitizers,
// which check memory safety rather than coverage of terrains, every sixth (Puget Sound's PNG, an SRTM
// tile with a lake and Alps, the Terrain-RGB tile; the Release run covers all). The sanitized e2e run
// was 394 s of the CI's 1057 s with every fourth.
inline std::vector<std::string> dems_for_heavy_tests() {
  std::vector<std::string> all = all_dems();
  if (!sanitized()) return all;
  std::vector<std::string> some;
  for (size_t i = 0; i < all.size(); i += 6) some.push_back(all[i]);
  return some;
}

}  // namespace testdata
